"""Parameters shared over wavelengths: one joint posterior and one sampler for all of them.

Most parameters of a film belong to one wavelength (``a``, ``tau`` of every film group) and are
sampled wavelength by wavelength (:mod:`bayespig.inference.sampler`). A parameter that is the
same at every wavelength (a card's albedo factor, the surface roughness, the binder index, a
film's thickness) couples the wavelengths: the posterior is then joint over all of them. This
module is the one home for such parameters; each kind is a *spec* (a subclass of
:class:`SharedParameter`) and :class:`JointLogPosterior` / :func:`sample_joint` handle any list
of specs the same way. The card factors (:mod:`bayespig.inference.card_factors`) are the
first spec.

The joint posterior
-------------------
Parameters ``[theta_λ (k per wavelength), phi (n_shared)]``: per wavelength a block
``theta_λ`` of ``k`` coordinates with a flat prior on a box, and ``phi`` the concatenated
sampled coordinates of the specs (e.g. ``log f`` per card), each spec with its own prior and
box. The likelihood is eq. (7) with a known relative error ``eps`` of every value, the forward
model evaluated with the specs' inputs (:meth:`SharedParameter.model_inputs`).

What a block holds is a *layout* (:class:`BlockLayout`: ``k``, the coordinates' names and
box, their place in the flat vector, the measured values, ``eps`` and
``predict(theta (W, n_wl, k), inputs) -> (W, n_wl, n_values)``). :class:`FilmLayout` is one
film problem, ``theta_λ = [a, log tau_1..G]`` (its film groups) with the box priors of
:class:`bayespig.likelihood.Priors` and the per-wavelength model
:class:`bayespig.likelihood.WavelengthModel` (a :class:`~bayespig.likelihood.ForwardModel`
passed to :class:`JointLogPosterior` is this layout); a pigment library's layout holds the
constants of the pigments being fitted (:mod:`bayespig.library.build`). The residual
coordinates, the moves, the start and the run below do not depend on the layout.

Residual coordinates
    Sampled are ``u = [r (n_wl * k), phi]`` with ``theta = theta_hat + r + S (phi - phi_0)``:
    ``theta_hat`` and ``S`` are the intercept and slope of the linear regression of ``theta``
    on ``phi`` over the draws of a short joint run (the adaptation, below), so that ``r`` is
    uncorrelated with ``phi``; that run itself uses the per-wavelength posterior median at the
    nominal ``phi_0`` (the pilot) and the damped Gauss-Newton sensitivity
    ``S = d theta_hat / d phi`` (:meth:`JointLogPosterior._sensitivity`). The damping,
    needed where a block is a ravine, also shrinks the sensitivity along the ravine: on
    Revigo 07A (a thick white film, ``tau`` ~ 15) it gives ``d log tau / d log f_white`` ~
    0.01-0.05 where the regression gives 2-3, and the conditional range of ``log f_white``
    given ``r`` was 0.002-0.005 against the marginal 0.010 (0.004-0.011 with the regression:
    the shared block moves as far as its posterior spreads). The map is a translation for every
    ``phi`` (unit Jacobian), so the density is the same in either coordinates; but a change of
    ``phi`` at fixed ``r`` moves every wavelength's ``theta`` along with it, which is what the
    data ask for. In ``u`` the wavelengths are independent given ``phi`` and only weakly coupled
    to it.
Block-wise moves
    :class:`BlockwiseMove`: every wavelength's block by differential evolution, each block
    accepted on its own likelihood term (given ``phi`` the wavelengths are independent), then
    the shared block on the whole log-posterior (then, where they apply, steps along a layout's
    exact scale symmetry and draws of weakly identified shared coordinates from their priors);
    a share :data:`JOINT_DE_WEIGHT` of whole-vector DE moves follows the correlations the
    residual coordinates leave.
Pilot start, adaptation
    :func:`sample_blocks` takes start draws of every block at ``phi = phi_0`` (for a film,
    :func:`sample_joint`: a per-wavelength run, the usual
    :func:`bayespig.inference.infer_problem`; for a library, a ball around a point fit), uses
    their medians as ``theta_hat``, and starts the walkers on them (picked independently per
    wavelength) with ``phi`` in a small ball around ``phi_0`` (a start whose shift
    ``S (phi - phi_0)`` would take a block out of its box starts at its picked physical point). A joint run of :data:`ADAPTATION_STEPS` steps from there gives the
    regression's ``theta_hat`` and ``S``; the run proper starts on its last walkers (the same
    physical points in the new coordinates). Where that run was still travelling or
    contracting (:func:`adaptation_settled`: the pilot's nominal ``phi`` far from the
    posterior), it is repeated from its end in the new coordinates, up to
    :data:`MAX_ADAPTATION_ROUNDS` runs, until two in a row are settled (a first run that is
    settled is enough, and then the draws are those of a single adaptation). Any fixed ``S`` leaves the target invariant; the
    adaptation's draws are not kept.
Run length, diagnostics
    Those of the per-wavelength runs (:func:`bayespig.inference.sampler._sample_stack`) on the
    joint vector, one vectorised table call per half-step for every wavelength of every walker.

Adding a shared parameter
-------------------------
A spec says, for its coordinates: their names (``labels``, one posterior variable
``variable`` over the dimension ``dimension``), the box of the sampled coordinate
(``lower``, ``upper``), the nominal value of the pilot (``nominal``) and the start spread
(``start_sd``), the prior (:meth:`~SharedParameter.log_prior`), the transform to the stored
physical value (:meth:`~SharedParameter.physical`), and how it enters the forward model at
every wavelength (:meth:`~SharedParameter.model_inputs`: keyword arrays of the
per-wavelength model, :class:`bayespig.likelihood.WavelengthModel`, which must accept them:
a new keyword there, and the tables behind it, is the forward-model side of a new spec). The
pilot runs the problem as given, so ``nominal`` is the value the problem implies without the
spec (``f = 1`` for a card, the roughness the problem is built with). Nothing else changes. The
parameters the open issues need, each one spec:

Roughness (issue 16)
    One coordinate ``log alpha`` per film (or per film group, or one for the set), prior
    log-uniform (or a half-normal in ``alpha``) on the tables' roughness range, physical value
    ``alpha``; :meth:`~SharedParameter.model_inputs` gives a ``roughness`` keyword (per row,
    per reflectance film) that the per-wavelength model interpolates along the tables'
    roughness axis, as it does ``r_s_scale`` for the card factors. ``roughness=number`` keeps
    it fixed (no spec).
Binder index ``n`` (issue 16)
    One coordinate ``n``, prior ``N(1.45, 0.05^2)`` truncated to the tables' ``n`` range; it
    enters every film (the interface's Fresnel terms and the card albedo seen from the binder,
    :func:`bayespig.physics.substrate.substrate_albedo_from_air`) through an ``n`` keyword of the
    per-wavelength model (tables with an ``n`` axis).
Film thickness (issue 17)
    :class:`bayespig.inference.film_thickness.FilmThickness`: one coordinate ``log h`` per
    film, prior normal around log of a measured thickness, else around 0 (relative
    thickness) with a stated sd, truncated; it enters through the model input ``thickness``
    (one per film) of the pigment library's layout (:mod:`bayespig.library.build`), whose
    block holds the pigments' constants (``a_i``, ``log sigma_i`` per wavelength, films mixed
    by their recipes). The prior keeps ``h * sigma`` identifiable.

Several specs at once (card factors and roughness) concatenate their coordinates in ``phi``
and are moved together in the shared block.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), eq. (7), section 3.4. Foreman-Mackey et al. (2013),
emcee's red-blue update; ter Braak (2006), differential evolution.
"""

from __future__ import annotations

import abc
import dataclasses
import functools

import numpy as np

from ..likelihood import Priors, multiplicative_normal_logpdf
from .moves import IndependentEnsemblesMove, ensemble_halves, gaussian_independence_proposal
from .outputs import STORED_DRAW_DTYPE
from .sampler import _sample_stack

__all__ = [
    "ADAPTATION_CONTRACTION",
    "ADAPTATION_DRIFT",
    "ADAPTATION_STEPS",
    "JOINT_DE_WEIGHT",
    "MAX_ADAPTATION_ROUNDS",
    "SENSITIVITY_DAMPING",
    "BlockLayout",
    "BlockwiseMove",
    "FilmLayout",
    "JointLogPosterior",
    "SharedParameter",
    "adaptation_settled",
    "pilot_draws",
    "sample_blocks",
    "sample_joint",
]

#: Values (draws x bands x measured values) predicted at once for the records of :func:`sample_joint`.
RECORD_VALUES = 2**23
#: Levenberg-Marquardt damping (relative to the mean eigenvalue of J^T J) of the blocks'
#: sensitivity to the shared parameters: in a ravine the undamped Gauss-Newton step along the
#: ravine is huge and only valid for tiny changes. Any sensitivity gives a valid sampler (it is a
#: change of coordinates with unit Jacobian); this one only sets how well the shared moves mix.
SENSITIVITY_DAMPING = 1e-3
#: Share of whole-vector DE moves among the block moves of the joint run: they follow
#: correlations between the blocks that the residual coordinates leave. With the regression's
#: coordinates 0, 0.1 and 0.2 are alike within the runs' spread (Revigo 07A: 1121 steps at 0,
#: 1376 at 0.2; 02B: 3389 at 0, 4197 at 0.1, 2514 at 0.2).
JOINT_DE_WEIGHT = 0.2
#: Share of the block updates of :class:`BlockwiseMove` that use a Gaussian independence
#: proposal per block instead of DE: DE from 16 walkers random-walks along a block's ravine
#: (Revigo 02B with DE blocks alone: tau_int of a log tau up to 68 steps, 4143 steps, 30 s;
#: the per-wavelength pilot with "gaussian-de" has tau_int <= 15). The 13 Revigo card-factor
#: films (``python benchmarks/substrate_factors.py --revigo-only``: method 4, substrate_sd 0.1,
#: 128 draws per chain, seed 0) took 10-36 s per film (median 18 s) with DE blocks alone,
#: before the run-length cap and the stored-draw check of :func:`bayespig.inference.sampler._run_verdict`;
#: with both, weight 0.8 gave 10-32 s (median 15 s, a scratch run) and weight 0.5 8.0-18.3 s
#: (median 11.9 s), none capped, every factor's stored draws R-hat <= 1.0071 and ESS >= 403.
BLOCK_GAUSSIAN_WEIGHT = 0.5
#: Random-walk steps along a layout's exact scale symmetry per update of a walker
#: (:meth:`BlockwiseMove._scale_moves`; they need no forward evaluation).
SCALE_MOVES_PER_UPDATE = 4
#: Steps of the adaptation run of :func:`sample_joint` whose draws give the blocks' sensitivity
#: to the shared parameters by regression (and the centre ``theta_hat``); then discarded.
ADAPTATION_STEPS = 300
#: Most adaptation runs of :func:`sample_blocks`. A pilot at the nominal shared values far from
#: their posterior (a Cornell paint: the pilot's binder index 1.45 and flake roughness 0.3, the
#: posterior's 1.52 and 0.79) makes the first adaptation a journey: its regression then
#: describes the journey, not the posterior's correlations, and the run proper mixes slowly
#: (``python benchmarks/joint_adaptation.py``, Krylon blue at 450/550/650 nm with flakes: with one
#: adaptation run 0.5 % of the shared moves accepted and the run capped at 4000 steps, ESS of the
#: roughness 216; with the rounds 16.3 %, converged in 1374 steps, ESS 3014). So the adaptation
#: is repeated from its own end, each repeat regressing on its second half, until two runs in a
#: row are settled (:func:`adaptation_settled`; one when the first is).
MAX_ADAPTATION_ROUNDS = 4
#: Shift of a shared coordinate's mean between the two halves of an adaptation run, in sds of
#: the run, above which the run has not settled. A stationary run's halves differ by about
#: ``sqrt(2 / ESS_half)`` sds (0.3 for ESS 25); a spurious extra round costs only its steps.
ADAPTATION_DRIFT = 0.5
#: Ratio of a shared coordinate's sd over the second half of an adaptation run to that over the
#: first below which the ensemble is still contracting (not settled); a stationary run's ratio
#: scatters by about ``1 / sqrt(ESS_half)`` around 1.
ADAPTATION_CONTRACTION = 0.9


class SharedParameter(abc.ABC):
    """Interface of one kind of parameter shared by all wavelengths (a spec; see the module docstring).

    Subclasses set the attributes and implement the methods below.

    Attributes
    ----------
    title : str
        What the parameters are, in words (e.g. ``"substrate factors"``; in messages).
    variable, dimension : str
        Posterior variable of the physical values and its dimension (e.g. ``"r_s_factor"``
        over ``"card"``).
    long_name, units : str
        The posterior variable's netCDF attributes (``units="1"``: dimensionless).
    labels : tuple of str
        One per coordinate (the dimension's coordinate values).
    coordinate_name : str
        Name of the sampled coordinate in ``parameter_names`` (e.g. ``"log_r_s_factor"``).
    lower, upper : numpy.ndarray
        Box of the sampled coordinates (the prior's support), shape (size,).
    nominal : numpy.ndarray
        Value of the pilot run (e.g. ``log f = 0``), inside the box.
    start_sd : numpy.ndarray
        Spread of the walkers' start around ``nominal`` in the sampled coordinate.
    attribute : str or None
        Name of the InferenceData attribute holding :meth:`describe` as JSON.
    prior_proposals : bool
        Whether :class:`BlockwiseMove` also draws these coordinates from their prior, one per
        walker and update, with the blocks held at their physical values (default False). For
        coordinates whose posterior is close to their prior, which the shared block's moves in
        the residual coordinates reach only slowly (a film that hides its cards bounds its
        thickness only from below). Needs a normal prior in the sampled coordinate, truncated to
        the box: ``prior_mean`` and ``prior_sd`` (shape (size,)).
    """

    title = "shared parameters"
    variable = dimension = coordinate_name = long_name = ""
    units = "1"
    attribute = None
    prior_proposals = False

    @property
    def size(self):
        """Number of sampled coordinates."""
        return len(self.labels)

    @abc.abstractmethod
    def log_prior(self, x):
        """Log prior density (up to a constant) of sampled coordinates ``x`` (W, size), shape (W,)."""

    @abc.abstractmethod
    def physical(self, x):
        """Stored physical values of ``x`` (W, size) (e.g. ``f = exp(log f)``)."""

    @abc.abstractmethod
    def model_inputs(self, x):
        """Keyword arrays of the per-wavelength model, one row per row of ``x`` (W, size)."""

    @abc.abstractmethod
    def describe(self):
        """The prior and the labels as a JSON-able dict (provenance)."""


class BlockLayout(abc.ABC):
    """What one wavelength's block of a :class:`JointLogPosterior` holds (see the module docstring).

    A layout says how many coordinates ``k`` each wavelength has, their box, where they sit in
    the flat vector of all blocks, the measured values and their relative error, and how the
    values follow from every wavelength's block and the specs' model inputs. Subclasses set
    the attributes and implement :meth:`predict`; everything else of the joint machinery
    (residual coordinates, moves, pilot start, run length) is the same for every layout.

    Attributes
    ----------
    wavelength_nm : numpy.ndarray
        Shape (n_wavelengths,) [nm].
    names : tuple of str
        Name of each of the ``k`` coordinates of a block (e.g. ``("a", "log_tau")``).
    lower, upper : numpy.ndarray
        Box of every block's coordinates (the prior's support; flat prior), (n_wavelengths, k).
    observed : numpy.ndarray
        Measured values, (n_wavelengths, n_values).
    eps : numpy.ndarray
        Known relative error of every value, broadcastable to ``observed``.
    flat_index : numpy.ndarray of int
        Position of every block coordinate in the flat vector ``theta`` (n_wavelengths, k);
        default coordinate-major (``j * n_wavelengths + i``).
    parameter_names : tuple of str
        Names of the flat residual coordinates (default ``r_<name>[<wavelength>]``).
    scale_symmetry : tuple or None
        ``(block mask (k,), spec variable)`` of an exact scale symmetry of the values
        (:attr:`JointLogPosterior.scale_direction`); None (default) without one.
    """

    scale_symmetry = None

    @property
    def n_wavelengths(self):
        """Number of wavelengths (blocks)."""
        return len(self.wavelength_nm)

    @property
    def size(self):
        """Coordinates per block ``k``."""
        return len(self.names)

    @property
    def flat_index(self):
        """Coordinate-major positions, (n_wavelengths, k)."""
        return np.arange(self.size)[None, :] * self.n_wavelengths + np.arange(self.n_wavelengths)[:, None]

    @property
    def parameter_names(self):
        """``r_<name>[<wavelength>]`` in flat order."""
        names = np.empty(self.n_wavelengths * self.size, dtype=object)
        for i, w in enumerate(self.wavelength_nm):
            for j, name in enumerate(self.names):
                names[self.flat_index[i, j]] = f"r_{name}[{w:g}]"
        return tuple(names)

    def centre(self):
        """A point inside every block's box, (n_wavelengths, k) (the box's middle by default)."""
        return 0.5 * (np.asarray(self.lower, dtype=float) + np.asarray(self.upper, dtype=float))

    @abc.abstractmethod
    def predict(self, theta, inputs):
        """Values of every wavelength, (W, n_wavelengths, n_values).

        Parameters
        ----------
        theta : numpy.ndarray
            Every wavelength's block, (W, n_wavelengths, k), inside the box.
        inputs : dict
            The specs' model inputs (:meth:`SharedParameter.model_inputs`), one row per walker.
        """

    def unpack(self, theta):
        """Physical values of the blocks (W, n_wavelengths, k) for :meth:`JointLogPosterior.unpack`
        (a tuple; default the blocks themselves)."""
        return (theta,)

    def reading(self, values):
        """The predicted readings from :meth:`predict`'s values (the same by default; a layout whose
        :meth:`predict` gives the mean of a reading before the instrument clips it at 0 clips it
        here)."""
        return values

    def log_density(self, theta, values):
        """Pointwise log-likelihood (W, n_wavelengths, n_values) of the values predicted from the
        blocks ``theta`` (W, n_wavelengths, k): eq. (7) with the known ``eps`` by default (a layout
        with noise parameters in its blocks, e.g. an additive floor, overrides it)."""
        return multiplicative_normal_logpdf(self.observed, values, self.eps)


class FilmLayout(BlockLayout):
    """The block ``[a, log tau_1..G]`` per wavelength of one film problem (its film groups).

    The flat order is ``[a (n_wl), log tau (n_wl * G)]``; the box that of
    :class:`bayespig.likelihood.Priors`; the values those of the per-wavelength model
    (:class:`bayespig.likelihood.WavelengthModel`) with the specs' keywords. A model with
    effect-pigment flakes (``ForwardModel(flakes=True)``) has one more coordinate per
    wavelength, ``log c`` (the flakes' reflectance, log-uniform on
    ``priors.flake_reflectance_range``), after the ``log tau``: blocks ``[a, log tau_1..G,
    log c]``, flat order ``[a (n_wl), log tau (n_wl * G), log c (n_wl)]``.

    Parameters
    ----------
    model : ForwardModel
        Isotropic.
    priors : Priors
    eps : float
        Known relative error for films without their own [-].
    """

    names = ("a", "log_tau")

    def __init__(self, model, priors, eps):
        problem = model.problem
        self.model = model
        self.problem = problem
        self.wavelength_nm = np.asarray(problem.wavelength_nm, dtype=float)
        self.n_groups = G = len(problem.groups)
        self.names = ("a",) + (("log_tau",) if G == 1 else tuple(f"log_tau[{g}]" for g in problem.groups))
        self.flakes = bool(getattr(model, "flakes", False))
        n_wl = self.n_wavelengths
        self.evaluate = model.at_wavelength(list(range(n_wl)))
        self.observed = np.stack([problem.observed(i) for i in range(n_wl)])
        self.eps = problem.known_eps(eps)
        low = [priors.a_range[0]] + [np.log(priors.tau_range[0])] * G
        high = [priors.a_range[1]] + [np.log(priors.tau_range[1])] * G
        if self.flakes:
            self.names = self.names + ("log_flake_reflectance",)
            low.append(np.log(priors.flake_reflectance_range[0]))
            high.append(np.log(priors.flake_reflectance_range[1]))
        self.lower = np.tile(np.array(low, dtype=float), (n_wl, 1))
        self.upper = np.tile(np.array(high, dtype=float), (n_wl, 1))

    @property
    def film_size(self):
        """Coordinates of a block that belong to the film model: ``1 + G`` (``+ 1`` with flakes)."""
        return 1 + self.n_groups + self.flakes

    @property
    def flat_index(self):
        """``[a (n_wl), log tau (n_wl * G), (log c (n_wl))]``: a wavelength's ``a`` at ``i``, its
        ``log tau_g`` at ``n_wl + i * G + g``, its ``log c`` at ``n_wl (1 + G) + i``."""
        n_wl, G = self.n_wavelengths, self.n_groups
        columns = [np.arange(n_wl)[:, None], n_wl + np.arange(n_wl * G).reshape(n_wl, G)]
        if self.flakes:
            columns.append((n_wl * (1 + G) + np.arange(n_wl))[:, None])
        return np.concatenate(columns, axis=1)

    @property
    def parameter_names(self):
        """``r_a[w]`` then ``r_log_tau[w,group]`` (then ``r_log_flake_reflectance[w]``)."""
        wl = [f"{w:g}" for w in self.wavelength_nm]
        names = [f"r_a[{w}]" for w in wl] + [f"r_log_tau[{w},{g}]" for w in wl for g in self.problem.groups]
        if self.flakes:
            names += [f"r_log_flake_reflectance[{w}]" for w in wl]
        return tuple(names)

    def predict(self, theta, inputs):
        """The film problem's values from ``[a, log tau, (log c)]`` per wavelength, (W, n_wl, n_values)."""
        W, n_wl = theta.shape[:2]
        member = np.tile(np.arange(n_wl), W)
        rows = {key: np.repeat(value, n_wl, axis=0) for key, value in inputs.items()}
        G = self.n_groups
        if self.flakes:
            rows["flake_reflectance"] = np.exp(theta[..., 1 + G]).reshape(-1)
        values = self.evaluate(theta[..., 0].reshape(-1), np.exp(theta[..., 1:1 + G]).reshape(W * n_wl, -1), None,
                               member=member, **rows)
        return values.reshape(W, n_wl, -1)

    def unpack(self, theta):
        """``a`` (W, n_wl) and ``tau`` (W, n_wl, G)."""
        return theta[..., 0], np.exp(theta[..., 1:1 + self.n_groups])

    def flake_reflectance_of(self, theta):
        """The flakes' reflectance ``c`` of every block (W, n_wl) [-] (None without flakes)."""
        return np.exp(theta[..., 1 + self.n_groups]) if self.flakes else None


class JointLogPosterior:
    """Joint log-posterior over all wavelengths with parameters shared by them.

    Sampled in the residual coordinates of the module docstring, ``u = [r (n_wl * k), phi
    (n_shared)]`` with ``r`` in the layout's flat order (for a film,
    ``[r_a (n_wl), r_log_tau (n_wl * G)]``). The interface of
    :class:`bayespig.likelihood.LogPosterior` (``n_dim``, ``parameter_names``,
    ``in_support``, call on ``u`` of shape (W, n_dim)), so that the sampler of the
    per-wavelength runs runs it with its run-length rule and diagnostics.

    Parameters
    ----------
    model : ForwardModel or BlockLayout
        A ForwardModel (isotropic) is the film layout :class:`FilmLayout` with ``priors`` and
        ``eps``; any other block content comes as its :class:`BlockLayout`.
    theta_hat : numpy.ndarray
        Centre of every block, shape (n_wavelengths, k) (for a film ``[a, log tau_1..G]``: the
        pilot's medians, :func:`pilot_draws`).
    specs : sequence of SharedParameter
    priors : Priors, optional
        Ranges of ``a`` and ``tau`` of a film layout (default :class:`~bayespig.likelihood.Priors`).
    eps : float
        Known relative measurement error of eq. (7) for films without their own [-] (film
        layout; a :class:`BlockLayout` carries its own).
    sensitivity : numpy.ndarray, optional
        ``S`` of the residual coordinates, shape (n_wavelengths * k, n_shared) in the flat
        order; default the damped Gauss-Newton one (:meth:`_sensitivity`).
    """

    def __init__(self, model, theta_hat, specs, priors=None, eps=0.01, sensitivity=None):
        priors = Priors() if priors is None else priors
        specs = tuple(specs)
        if not isinstance(model, BlockLayout) and model.g != "isotropic":
            raise ValueError(f"{' and '.join(s.title for s in specs) or 'shared parameters'} are "
                             "implemented for isotropic scattering (g fixed at 0)")
        if not (np.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be a positive number, got {eps!r}")
        if not specs or any(not isinstance(s, SharedParameter) for s in specs):
            raise TypeError("specs must be a non-empty sequence of SharedParameter")
        layout = model if isinstance(model, BlockLayout) else FilmLayout(model, priors, eps)
        self.layout = layout
        self.model = getattr(layout, "model", None)
        self.specs = specs
        self.priors = priors
        self.n_wavelengths = n_wl = layout.n_wavelengths
        self.block_size = k = layout.size
        self.n_groups = getattr(layout, "n_groups", None)
        self.observed = np.asarray(layout.observed, dtype=float)
        self.eps = layout.eps
        self.n_shared = sum(s.size for s in specs)
        self.shared_lower = np.concatenate([np.asarray(s.lower, dtype=float) for s in specs])
        self.shared_upper = np.concatenate([np.asarray(s.upper, dtype=float) for s in specs])
        self.shared_nominal = np.concatenate([np.asarray(s.nominal, dtype=float) for s in specs])
        n_theta = n_wl * k
        #: Coordinates of each wavelength's block in ``u`` (n_wl, k), and of the shared block.
        self.blocks = np.asarray(layout.flat_index, dtype=int)
        if self.blocks.shape != (n_wl, k) or not np.array_equal(np.sort(self.blocks.ravel()), np.arange(n_theta)):
            raise ValueError(f"the layout's flat_index must be a permutation of 0..{n_theta - 1} in shape "
                             f"{(n_wl, k)}, got shape {self.blocks.shape}")
        self.theta_lower = self._flat(np.broadcast_to(np.asarray(layout.lower, dtype=float), (n_wl, k)))
        self.theta_upper = self._flat(np.broadcast_to(np.asarray(layout.upper, dtype=float), (n_wl, k)))
        theta_hat = np.asarray(theta_hat, dtype=float).reshape(n_wl, k)
        self.theta_hat = np.clip(self._flat(theta_hat), self.theta_lower, self.theta_upper)
        self.shared_slice = slice(n_theta, n_theta + self.n_shared)
        #: Each spec's coordinates within ``phi``.
        self.spec_slices = []
        start = 0
        for spec in specs:
            self.spec_slices.append(slice(start, start + spec.size))
            start += spec.size
        if sensitivity is None:
            self.sensitivity = self._sensitivity()  # (n_wl * k, n_shared)
        else:
            self.sensitivity = np.asarray(sensitivity, dtype=float)
            if self.sensitivity.shape != (n_theta, self.n_shared):
                raise ValueError(f"sensitivity must have shape {(n_theta, self.n_shared)}, "
                                 f"got {self.sensitivity.shape}")
        # a box holding the support in u (for the sampler's start ball and straggler moves)
        reach = np.abs(self.sensitivity) @ np.maximum(np.abs(self.shared_lower - self.shared_nominal),
                                                      np.abs(self.shared_upper - self.shared_nominal))
        self.lower = np.concatenate([self.theta_lower - self.theta_hat - reach, self.shared_lower])
        self.upper = np.concatenate([self.theta_upper - self.theta_hat + reach, self.shared_upper])
        self.parameter_names = tuple(layout.parameter_names) + tuple(
            f"{s.coordinate_name}[{label}]" for s in specs for label in s.labels)

    @property
    def n_dim(self):
        """Number of parameters."""
        return self.n_wavelengths * self.block_size + self.n_shared

    def _flat(self, blocks):
        """The flat vector(s) of blocks (..., n_wl, k) in the layout's order, (..., n_wl * k)."""
        flat = np.empty(blocks.shape[:-2] + (self.blocks.size,))
        flat[..., self.blocks] = blocks
        return flat

    def blocks_of(self, theta):
        """Every wavelength's block (W, n_wl, k) from flat ``theta`` (W, n_wl * k)."""
        return theta[:, self.blocks]

    def _model_inputs(self, phi):
        """The specs' keyword arrays of the forward model, one row per row of ``phi``."""
        inputs = {}
        for spec, part in zip(self.specs, self.spec_slices):
            for key, value in spec.model_inputs(phi[:, part]).items():
                if key in inputs:
                    raise ValueError(f"two shared parameters set the model input {key!r}")
                inputs[key] = value
        return inputs

    def _predict_theta(self, theta, phi):
        """Values of every wavelength, (W, n_wl, n_values), from physical flat ``theta`` and ``phi``."""
        return self.layout.predict(self.blocks_of(theta), self._model_inputs(phi))

    def _sensitivity(self, step=1e-4):
        """``d theta_hat / d phi`` per wavelength by Gauss-Newton on the weighted residuals.

        ``S = -(J_theta^T J_theta)^+ J_theta^T J_phi`` with ``J`` the derivatives of the
        residuals ``(x_obs / x_model - 1) / eps`` (central differences at ``phi_0``), damped by
        :data:`SENSITIVITY_DAMPING`; directions the data do not constrain (e.g. ``tau`` of a
        film that hides its card) get no shift.
        """
        n_wl, C = self.n_wavelengths, self.n_shared
        base = np.concatenate([self.theta_hat, self.shared_nominal])
        inner = np.clip(base[:-C], self.theta_lower + step, self.theta_upper - step)
        base[:-C] = inner
        steps = np.eye(base.size) * step
        points = np.concatenate([base + steps, base - steps])
        # a prediction of exactly 0 (a reading clipped by the incidence offset) gives an infinite
        # residual and an undefined difference: such values carry no sensitivity (0 below)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            values = self.layout.reading(self._predict_theta(points[:, :-C], points[:, -C:]))
            residual = (self.observed / values - 1.0) / self.eps
            derivative = (residual[:base.size] - residual[base.size:]) / (2.0 * step)  # (n_dim, n_wl, n_values)
        derivative = np.nan_to_num(derivative, nan=0.0, posinf=0.0, neginf=0.0)
        out = np.zeros((n_wl * self.block_size, C))
        for i in range(n_wl):
            rows = self.blocks[i]
            J_theta = derivative[rows, i].T  # (n_values, k)
            J_phi = derivative[-C:, i].T  # (n_values, C)
            normal = J_theta.T @ J_theta
            damping = SENSITIVITY_DAMPING * np.trace(normal) / normal.shape[0] + 1e-300
            out[rows] = -np.linalg.solve(normal + damping * np.eye(normal.shape[0]), J_theta.T @ J_phi)
        return out

    def theta_of(self, u):
        """Physical flat ``theta`` (n_wl * k) and the shared coordinates ``phi`` from ``u``."""
        u = np.atleast_2d(u)
        phi = u[:, self.shared_slice]
        return self.theta_hat + u[:, :self.shared_slice.start] + (phi - self.shared_nominal) @ self.sensitivity.T, phi

    def u_of(self, theta, phi):
        """The inverse of :meth:`theta_of`: ``u`` from flat ``theta`` (W, n_wl * k) and ``phi`` (W, n_shared)."""
        theta, phi = np.atleast_2d(theta), np.atleast_2d(phi)
        return np.concatenate([theta - self.theta_hat - (phi - self.shared_nominal) @ self.sensitivity.T, phi],
                              axis=1)

    def regression(self, u):
        """Centre and sensitivity of the residual coordinates that make ``r`` uncorrelated with ``phi`` over ``u``.

        The least-squares fit ``theta = theta_hat + S (phi - phi_0)`` over the points ``u``
        (W, n_dim), e.g. draws of this posterior.

        Returns
        -------
        tuple
            ``(theta_hat (n_wl, k), S (n_wl * k, n_shared))``, the arguments of a new
            :class:`JointLogPosterior`.
        """
        theta, phi = self.theta_of(u)
        shift = phi - self.shared_nominal
        design = np.concatenate([np.ones((shift.shape[0], 1)), shift - shift.mean(axis=0)], axis=1)
        coef = np.linalg.lstsq(design, theta, rcond=None)[0]
        slope = coef[1:].T  # (n_theta, n_shared)
        centre = coef[0] - slope @ shift.mean(axis=0)
        return centre[self.blocks], slope

    def unpack(self, u):
        """The layout's physical block values (for a film ``a`` (W, n_wl) and ``tau`` (W, n_wl, G)),
        then each spec's physical values (W, size)."""
        theta, phi = self.theta_of(u)
        physical = [spec.physical(phi[:, part]) for spec, part in zip(self.specs, self.spec_slices)]
        return (*self.layout.unpack(self.blocks_of(theta)), *physical)

    def _shared_inside(self, phi):
        return ((phi >= self.shared_lower) & (phi <= self.shared_upper)).all(axis=1)

    @functools.cached_property
    def prior_proposal_columns(self):
        """``(columns, mean, sd)`` of the shared coordinates whose specs opt into prior proposals
        (:attr:`SharedParameter.prior_proposals`): their positions within ``phi`` and their
        normal priors' means and sds; None when no spec does."""
        columns, mean, sd = [], [], []
        for spec, part in zip(self.specs, self.spec_slices):
            if spec.prior_proposals:
                columns.append(np.arange(part.start, part.stop))
                mean.append(np.broadcast_to(np.asarray(spec.prior_mean, dtype=float), (spec.size,)))
                sd.append(np.broadcast_to(np.asarray(spec.prior_sd, dtype=float), (spec.size,)))
        if not columns:
            return None
        return np.concatenate(columns), np.concatenate(mean), np.concatenate(sd)

    @functools.cached_property
    def _scale_symmetry(self):
        """``(block mask, spec, spec's slice of phi)`` of the layout's ``scale_symmetry``, None
        without one or without its spec among the sampled ones."""
        symmetry = self.layout.scale_symmetry
        if symmetry is None:
            return None
        mask, variable = symmetry
        return next(((mask, spec, part) for spec, part in zip(self.specs, self.spec_slices)
                     if spec.variable == variable), None)

    @functools.cached_property
    def scale_direction(self):
        """Direction in ``u`` of the layout's exact scale symmetry, (n_dim,), or None.

        A layout whose values depend on its thickness-like shared coordinates ``log h`` and its
        extinction-like block coordinates ``log sigma`` only through ``log h + log sigma`` (a
        pigment library: ``tau = h sum_i D_i sigma_i``) declares it as ``scale_symmetry =
        (block_mask (k,), spec_variable)``: ``log h + delta``, ``log sigma - delta`` leaves every
        value unchanged. In ``u`` the shift of ``phi`` also moves the blocks by ``S delta``,
        which ``r`` takes back.
        """
        symmetry = self._scale_symmetry
        if symmetry is None:
            return None
        mask, _, part = symmetry
        d_phi = np.zeros(self.n_shared)
        d_phi[part] = 1.0
        d_theta = -self._flat(np.broadcast_to(np.asarray(mask, dtype=float), (self.n_wavelengths, self.block_size)))
        return np.concatenate([d_theta - self.sensitivity @ d_phi, d_phi])

    @functools.cached_property
    def scale_step_sd(self):
        """Sd of the steps along :attr:`scale_direction`: ``2.38`` times the prior sd of the mean
        of the symmetry's shared coordinates, ``(sum_j sd_j^-2)^-1/2`` (what bounds the common
        scale when the data do not; 2.38: the optimal one-dimensional random walk, Roberts et
        al. 1997). None without the symmetry."""
        if self._scale_symmetry is None:
            return None
        spec = self._scale_symmetry[1]
        sd = np.broadcast_to(np.asarray(spec.prior_sd, dtype=float), (spec.size,))
        return float(2.38 / np.sqrt(np.sum(sd ** -2.0)))

    def in_support(self, u):
        """Boolean mask of parameter vectors inside the prior's support."""
        theta, phi = self.theta_of(u)
        return ((theta >= self.theta_lower) & (theta <= self.theta_upper)).all(axis=1) & self._shared_inside(phi)

    def predict(self, u):
        """Predicted values (readings) of every wavelength, shape (W, n_wavelengths, n_values)."""
        theta, phi = self.theta_of(u)
        return self.layout.reading(self._predict_theta(theta, phi))

    def log_likelihood(self, u):
        """Pointwise log-likelihood of eq. (7), shape (W, n_wavelengths, n_values)."""
        theta, phi = self.theta_of(u)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return self.layout.log_density(self.blocks_of(theta), self._predict_theta(theta, phi))

    def wavelength_terms(self, u):
        """Log-likelihood of each wavelength, (W, n_wl); ``-inf`` where its block or ``phi``
        leave the prior's box."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        theta, phi = self.theta_of(u)
        inside = (theta >= self.theta_lower) & (theta <= self.theta_upper)
        block_ok = inside[:, self.blocks].all(axis=2)
        block_ok &= self._shared_inside(phi)[:, None]
        terms = np.full((u.shape[0], self.n_wavelengths), -np.inf)
        rows = block_ok.any(axis=1)
        if rows.any():
            safe = np.clip(theta[rows], self.theta_lower, self.theta_upper)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                values = self.layout.log_density(self.blocks_of(safe),
                                                 self._predict_theta(safe, phi[rows])).sum(axis=2)
            values[~np.isfinite(values)] = -np.inf
            terms[rows] = np.where(block_ok[rows], values, -np.inf)
        return terms

    def log_prior_shared(self, u):
        """Log-density of the shared parameters' priors (up to a constant), (W,)."""
        phi = np.atleast_2d(u)[:, self.shared_slice]
        total = self.specs[0].log_prior(phi[:, self.spec_slices[0]])
        for spec, part in zip(self.specs[1:], self.spec_slices[1:]):
            total = total + spec.log_prior(phi[:, part])
        return total

    def __call__(self, u, member=None):
        """Log-posterior (up to a constant), shape (W,); ``member`` is ignored (one joint problem)."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        return self.log_prior_shared(u) + self.wavelength_terms(u).sum(axis=1)


class BlockwiseMove:
    """Red-blue ensemble update of a :class:`JointLogPosterior`, block by block.

    Within each of ``n_ensembles`` independent ensembles (one arviz chain each, as
    :class:`bayespig.inference.IndependentEnsemblesMove`), every walker of one half is updated
    from the other half in two steps:

    1. every wavelength's block ``(r_a, r_log_tau)`` by a differential-evolution proposal
       (ter Braak 2006; ``gamma = 2.38 / sqrt(2 d_block)``) from the block's values in two
       walkers of the other half or, in a fraction :data:`BLOCK_GAUSSIAN_WEIGHT` of the
       updates, by the Gaussian independence proposal of
       :class:`bayespig.inference.IndependentEnsemblesMove` (``"gaussian"``) fitted per block to
       the other half, with its Hastings factor; each block accepted or rejected **on its own**
       with its own likelihood term: given ``phi`` the wavelengths are independent, so the
       joint kernel is the product of the blocks' Metropolis-Hastings kernels;
    2. the shared coordinates ``phi`` by the same proposal in their block, accepted on the
       whole log-posterior;
    3. where the layout has an exact scale symmetry (:attr:`JointLogPosterior.scale_direction`:
       a pigment library's thicknesses and extinctions), :data:`SCALE_MOVES_PER_UPDATE`
       random-walk steps along it, accepted on the priors alone (the values do not change);
    4. where specs opt in (:attr:`SharedParameter.prior_proposals`: the films' thicknesses), one
       of their coordinates per walker drawn from its prior with the blocks held at their
       physical values, accepted on the likelihood ratio.

    Steps 3 and 4 are for parameters the data bound only on one side or not at all. Revigo's
    base stage (zinc white and bone black from 07A, 07C-07F; three of the films hide their
    cards, so their thicknesses are bounded only from below, and the common scale of the
    thicknesses and extinctions only by the thickness prior): with steps 1-2 alone 3.6 % of the
    shared proposals were accepted and the thicknesses' autocorrelation times were 190-314 steps
    (6000-step cap reached); with 3 and 4, 40 % and 42 % accepted, the thicknesses no longer the
    slowest coordinates (``python benchmarks/base_stage.py``).

    Mixing is then that of a few-parameter problem per block instead of one of
    ``n_wavelengths * (1 + G) + n_shared`` dimensions. Both proposals are symmetric and depend
    on the other half only, so detailed balance holds (Foreman-Mackey et al. 2013).

    Parameters
    ----------
    log_post : JointLogPosterior
    n_ensembles : int
    """

    def __init__(self, log_post, n_ensembles, gaussian_weight=None):
        self.log_post = log_post
        self.n_ensembles = int(n_ensembles)
        self.gaussian_weight = BLOCK_GAUSSIAN_WEIGHT if gaussian_weight is None else float(gaussian_weight)
        self.frozen = None  # the interface of IndependentEnsemblesMove (one member: never frozen)
        #: Shared-block proposals made and accepted, and block updates made and accepted, over the
        #: move's life (the run record's ``shared_acceptance`` and ``block_acceptance``).
        self.shared_proposed = self.shared_accepted = self.blocks_proposed = self.blocks_accepted = 0
        #: The same of the scale-symmetry steps and of the prior proposals (steps 3 and 4).
        self.scale_proposed = self.scale_accepted = self.prior_proposed = self.prior_accepted = 0
        # every walker's coordinates and wavelength terms at the end of the last update: the
        # terms of a walker no other move has changed since are not evaluated again
        self._coords = self._terms = None

    def _current_terms(self, current, index):
        """Wavelength terms of the walkers ``index`` at ``current``, from the cache where it holds them."""
        if self._coords is None:
            return self.log_post.wavelength_terms(current)
        terms = self._terms[index].copy()
        stale = ~(self._coords[index] == current).all(axis=1)
        if stale.any():
            terms[stale] = self.log_post.wavelength_terms(current[stale])
        return terms

    def tune(self, state, accepted):
        """No tuning (emcee's interface)."""

    @staticmethod
    def _de_step(s, c, columns, random):
        """DE proposals of the coordinates ``columns`` (..., k) for walkers ``s`` (E, h, d) from ``c``."""
        n_ens, h, _ = s.shape
        m = c.shape[1]
        shape = (n_ens, h) + columns.shape[:-1]
        first = random.randint(0, m, size=shape)
        second = random.randint(0, m - 1, size=shape)
        second += second >= first
        ens = np.arange(n_ens).reshape((n_ens,) + (1,) * (len(shape) - 1))
        d = columns.shape[-1]
        gamma = 2.38 / np.sqrt(2.0 * d) * (1.0 + 1e-5 * random.randn(*shape))
        diff = c[ens[..., None], first[..., None], columns] - c[ens[..., None], second[..., None], columns]
        return gamma[..., None] * diff

    @staticmethod
    def _gaussian_step(s, c, columns, random):
        """:func:`~bayespig.inference.moves.gaussian_independence_proposal` of each block ``columns``
        (n_blocks, k) per ensemble: proposals (E, h, n_blocks, k) and Hastings factors (E, h, n_blocks)."""
        x = np.moveaxis(s[:, :, columns], 2, 1)  # (E, n_blocks, h, k)
        others = np.moveaxis(c[:, :, columns], 2, 1)
        q, factor = gaussian_independence_proposal(x, others, random)
        return np.moveaxis(q, 1, 2), np.moveaxis(factor, 1, 2)

    def _scale_moves(self, moved, log_prob, terms, random):
        """:data:`SCALE_MOVES_PER_UPDATE` random-walk Metropolis steps of every walker along the
        layout's exact scale symmetry (:attr:`JointLogPosterior.scale_direction`): the values,
        hence the wavelength terms, do not change, so only the priors decide."""
        lp = self.log_post
        direction, step_sd = lp.scale_direction, lp.scale_step_sd
        any_taken = np.zeros(moved.shape[0], dtype=bool)
        for _ in range(SCALE_MOVES_PER_UPDATE):
            q = moved + (step_sd * random.randn(moved.shape[0]))[:, None] * direction
            new = np.where(lp.in_support(q), lp.log_prior_shared(q) + terms.sum(axis=1), -np.inf)
            with np.errstate(invalid="ignore"):
                take = new - log_prob > np.log(random.rand(moved.shape[0]))
            moved = np.where(take[:, None], q, moved)
            log_prob = np.where(take, new, log_prob)
            any_taken |= take
            self.scale_proposed += take.size
            self.scale_accepted += int(take.sum())
        return moved, log_prob, any_taken

    def _prior_proposals(self, moved, terms, random):
        """Every walker: one of the opted-in shared coordinates (:attr:`SharedParameter.prior_proposals`)
        drawn from its normal prior, the blocks held at their physical values (``r`` takes back
        the shift ``S (phi' - phi)``: unit Jacobian), accepted on the likelihood ratio (the
        proposal density cancels the prior's; a draw outside the prior's box is rejected)."""
        lp = self.log_post
        columns, mean, sd = lp.prior_proposal_columns
        n = moved.shape[0]
        pick = random.randint(0, columns.size, size=n)
        shift = np.zeros((n, lp.n_shared))
        rows = np.arange(n)
        current = moved[rows, lp.shared_slice.start + columns[pick]]
        shift[rows, columns[pick]] = mean[pick] + sd[pick] * random.randn(n) - current
        q = moved.copy()
        q[:, lp.shared_slice] += shift
        q[:, :lp.shared_slice.start] -= shift @ lp.sensitivity.T
        new_terms = lp.wavelength_terms(q)
        with np.errstate(invalid="ignore"):
            take = new_terms.sum(axis=1) - terms.sum(axis=1) > np.log(random.rand(n))
        self.prior_proposed += take.size
        self.prior_accepted += int(take.sum())
        return np.where(take[:, None], q, moved), np.where(take[:, None], new_terms, terms), take

    def propose(self, model, state):
        """One red-blue update of every walker of every ensemble (emcee's Move interface)."""
        lp = self.log_post
        n_total, n_dim = state.coords.shape
        random = model.random
        accepted = np.zeros(n_total, dtype=bool)
        shared_columns = np.arange(lp.shared_slice.start, lp.shared_slice.stop)
        for active, other in ensemble_halves(n_total, self.n_ensembles, random, owner=type(self).__name__):
            s, c = state.coords[active], state.coords[other]
            index = active.reshape(-1)
            current = s.reshape(-1, n_dim)
            # 1. wavelength blocks, each accepted on its own term
            q = current.copy()
            if random.rand() < self.gaussian_weight:
                proposed, factor = self._gaussian_step(s, c, lp.blocks, random)
                q[:, lp.blocks] = proposed.reshape(index.size, *lp.blocks.shape)
                factor = factor.reshape(index.size, -1)
            else:
                q[:, lp.blocks] += self._de_step(s, c, lp.blocks, random).reshape(index.size, *lp.blocks.shape)
                factor = 0.0
            old_terms, new_terms = self._current_terms(current, index), lp.wavelength_terms(q)
            with np.errstate(invalid="ignore"):
                take = new_terms - old_terms + factor > np.log(random.rand(*new_terms.shape))
            moved = current.copy()
            moved_cols = np.where(take[..., None], q[:, lp.blocks], current[:, lp.blocks])
            moved[:, lp.blocks] = moved_cols
            terms = np.where(take, new_terms, old_terms)
            # 2. the shared block, on the whole log-posterior
            q = moved.copy()
            q[:, shared_columns] += self._de_step(s, c, shared_columns[None], random).reshape(index.size, -1)
            before = lp.log_prior_shared(moved) + terms.sum(axis=1)
            after_terms = lp.wavelength_terms(q)
            after = lp.log_prior_shared(q) + after_terms.sum(axis=1)
            with np.errstate(invalid="ignore"):
                ok = after - before > np.log(random.rand(index.size))
            moved[ok] = q[ok]
            self.shared_proposed += ok.size
            self.shared_accepted += int(ok.sum())
            self.blocks_proposed += take.size
            self.blocks_accepted += int(take.sum())
            accepted[index] = ok | take.any(axis=1)
            if self._coords is None or self._coords.shape != state.coords.shape:
                self._coords = np.full(state.coords.shape, np.nan)
                self._terms = np.zeros((n_total, lp.n_wavelengths))
            terms = np.where(ok[:, None], after_terms, terms)
            log_prob = np.where(ok, after, before)
            # 3. the layout's exact scale symmetry (no forward evaluation: the values do not change)
            if lp.scale_direction is not None:
                moved, log_prob, scaled = self._scale_moves(moved, log_prob, terms, random)
                accepted[index] |= scaled
            # 4. shared coordinates drawn from their priors, the blocks held at their physical values
            if lp.prior_proposal_columns is not None:
                moved, terms, drawn = self._prior_proposals(moved, terms, random)
                log_prob = lp.log_prior_shared(moved) + terms.sum(axis=1)
                accepted[index] |= drawn
            state.coords[index] = moved
            state.log_prob[index] = log_prob
            self._coords[index] = moved
            self._terms[index] = terms
        return state, accepted


def pilot_draws(idata):
    """Every pooled draw ``[a, log tau_1..G]`` per wavelength of a per-wavelength run.

    Parameters
    ----------
    idata : arviz.InferenceData
        From :func:`bayespig.inference.infer_problem` (isotropic, at the nominal shared values).

    Returns
    -------
    numpy.ndarray
        Shape (n_chains * n_draws, n_wavelengths, 1 + G).
    """
    a_pilot = np.asarray(idata.posterior["a"].values, dtype=float)
    tau_pilot = (np.asarray(idata.posterior["tau_group"].values, dtype=float) if "tau_group" in idata.posterior
                 else np.asarray(idata.posterior["tau"].values, dtype=float)[..., None])
    draws = np.concatenate([a_pilot[..., None], np.log(tau_pilot)], axis=-1)  # (chain, draw, wl, 1 + G)
    return draws.reshape(-1, *draws.shape[2:])


def sample_blocks(model, specs, draws, settings, joint_seed, start_seed, priors=None, eps=0.01):
    """Joint run over all wavelengths of any block layout with the shared parameters ``specs``.

    The machinery of the module docstring: residual coordinates centred on the medians of
    ``draws``, walkers started on ``draws`` (picked independently per wavelength) with ``phi``
    in a small ball around the specs' ``nominal``, an adaptation run of
    :data:`ADAPTATION_STEPS` steps whose regression gives the centre and sensitivity of the run
    proper, :class:`BlockwiseMove` mixed with whole-vector DE, and the run-length rule and
    diagnostics of the per-wavelength runs on the thinned joint chain.

    Parameters
    ----------
    model : ForwardModel or BlockLayout
        What the blocks hold (a ForwardModel: the film layout, :class:`FilmLayout`).
    specs : sequence of SharedParameter
    draws : numpy.ndarray
        Start points of the blocks, (n_points, n_wavelengths, k), inside the box (a pilot's
        draws, :func:`pilot_draws`, or any ball around a point fit): their medians are the
        first ``theta_hat``.
    settings : InferenceSettings
        Walkers are raised to what the blocks need (a few per dimension of the largest block).
    joint_seed, start_seed : numpy.random.SeedSequence
        Seed the sampler, and the walkers' start.
    priors : Priors, optional
    eps : float
        Those of a film layout (:class:`JointLogPosterior`).

    Returns
    -------
    tuple
        ``(run, settings, joint)``: the run record of :func:`bayespig.inference.sampler._sample_stack`
        (``theta``: the draws in ``u``, (chain, draw, n_dim); ``autocorr_time`` per coordinate
        of ``u``; ``n_steps``, ``max_steps_reached``, ...; ``adaptation_rounds``, the
        adaptation runs before it, 1 to :data:`MAX_ADAPTATION_ROUNDS`; and ``shared_acceptance``
        and ``block_acceptance``, the shares of :class:`BlockwiseMove`'s shared-block proposals
        and of its wavelength-block updates accepted in the run proper, ``scale_acceptance`` and
        ``prior_proposal_acceptance`` those of its steps 3 and 4, NaN where they do not apply),
        the settings used, and the
        :class:`JointLogPosterior` of the run proper (its :meth:`~JointLogPosterior.unpack`
        gives the physical values).
    """
    draws = np.asarray(draws, dtype=float)
    theta_hat = np.median(draws, axis=0)
    joint = JointLogPosterior(model, theta_hat, specs, priors, eps)
    n_wl, k = joint.n_wavelengths, joint.block_size
    # blocks of k (a wavelength) and n_shared parameters: DE needs a few walkers per dimension
    n_walkers = max(settings.n_walkers, 4 * max(k, joint.n_shared), 6)
    used = dataclasses.replace(settings, n_walkers=n_walkers + n_walkers % 2)
    # walkers start on the draws (independently per wavelength) with phi ~ phi_0
    rng = np.random.default_rng(start_seed)
    n_total = used.n_ensembles * used.n_walkers
    picked = draws[rng.integers(0, draws.shape[0], size=(n_total, n_wl)), np.arange(n_wl)]  # (n, wl, k)
    residual = joint._flat(picked) - joint.theta_hat
    spread = np.concatenate([np.asarray(s.start_sd, dtype=float) for s in joint.specs])
    start = np.concatenate([residual, rng.normal(joint.shared_nominal, spread, (n_total, joint.n_shared))], axis=1)
    start[:, joint.shared_slice] = np.clip(start[:, joint.shared_slice], joint.shared_lower, joint.shared_upper)
    # a start whose shift S (phi - phi_0) takes a block out of its box (a block near its
    # box's edge, e.g. a white's a ~ 1e-4) starts at its picked physical point instead
    outside = ~joint.in_support(start)
    if outside.any():
        start[outside] = joint.u_of(joint._flat(picked[outside]), start[outside][:, joint.shared_slice])
    parent_seed = joint_seed
    adapt_seed, joint_seed = parent_seed.spawn(2)

    def run_joint(posterior, run_settings, seed, walkers):
        blockwise = BlockwiseMove(posterior, used.n_ensembles)
        record = _sample_stack(posterior, [posterior], np.zeros((1, posterior.n_dim)), run_settings, [seed],
                               moves=[(blockwise, 1.0 - JOINT_DE_WEIGHT),
                                      (IndependentEnsemblesMove("de", used.n_ensembles), JOINT_DE_WEIGHT)],
                               start_walkers=walkers, dense_check=True, stored_check=posterior.shared_slice)[0]
        record["shared_acceptance"] = blockwise.shared_accepted / max(blockwise.shared_proposed, 1)
        record["block_acceptance"] = blockwise.blocks_accepted / max(blockwise.blocks_proposed, 1)
        record["scale_acceptance"] = (blockwise.scale_accepted / blockwise.scale_proposed
                                      if blockwise.scale_proposed else float("nan"))
        record["prior_proposal_acceptance"] = (blockwise.prior_accepted / blockwise.prior_proposed
                                               if blockwise.prior_proposed else float("nan"))
        return record

    # adaptation: a short run whose draws give the regression's centre and sensitivity
    adapt_steps = max(ADAPTATION_STEPS, used.steps_kept)
    adapt_settings = dataclasses.replace(used, min_steps=adapt_steps, max_steps=adapt_steps, check_interval=adapt_steps)
    walkers = start
    settled_rounds = 0
    for round_index in range(MAX_ADAPTATION_ROUNDS):
        # the first round's seed is the one a single adaptation has always had (the same draws
        # when it settles); further rounds take further children of the same parent
        round_seed = adapt_seed if round_index == 0 else parent_seed.spawn(1)[0]
        adaptation = run_joint(joint, adapt_settings, round_seed, walkers)
        # (ensemble, walker, step, n_dim): the stored draws of every walker in time order
        history = adaptation["theta"].reshape(used.n_ensembles, used.n_walkers, used.steps_kept, joint.n_dim)
        settled = adaptation_settled(history, joint.shared_slice)
        adapted = history if settled else history[:, :, history.shape[2] // 2:]
        # a first round that settles is enough; after a journey, two settled rounds in a row
        # (the first settled one's regression still carries some of the journey)
        settled_rounds = settled_rounds + 1 if settled else 0
        done = settled_rounds >= (1 if round_index == 0 else 2) or round_index == MAX_ADAPTATION_ROUNDS - 1
        theta_hat, sensitivity = joint.regression(adapted.reshape(-1, joint.n_dim))
        physical_last = joint.theta_of(history[:, :, -1].reshape(-1, joint.n_dim))
        joint = JointLogPosterior(model, theta_hat, specs, priors, eps, sensitivity=sensitivity)
        walkers = joint.u_of(*physical_last)
        if done:
            break
    run = run_joint(joint, used, joint_seed, walkers)
    run["adaptation_rounds"] = round_index + 1
    return run, used, joint


def adaptation_settled(history, shared_slice, drift=ADAPTATION_DRIFT, contraction=ADAPTATION_CONTRACTION):
    """Whether an adaptation run's shared coordinates were stationary (no transient left).

    Parameters
    ----------
    history : numpy.ndarray
        The run's stored draws in time order, (n_ensembles, n_walkers, n_steps, n_dim).
    shared_slice : slice
        The shared coordinates ``phi`` within ``n_dim``.
    drift : float
        Largest accepted shift of a coordinate's mean between the run's two halves, in units of
        its sd over the whole run.
    contraction : float
        Smallest accepted ratio of a coordinate's sd over the second half to that over the first.

    Returns
    -------
    bool
        True when, for every shared coordinate, the mean over the second half of the steps lies
        within ``drift`` sds of the mean over the first half and the ensemble did not contract
        (sd ratio >= ``contraction``): the run sampled the posterior rather than travelled or
        shrank towards it, and its regression describes the posterior's correlations.
    """
    phi = np.asarray(history, dtype=float)[..., shared_slice]
    half = phi.shape[2] // 2
    if half < 2:
        return True
    first = phi[:, :, :half].reshape(-1, phi.shape[-1])
    second = phi[:, :, half:].reshape(-1, phi.shape[-1])
    sd = phi.reshape(-1, phi.shape[-1]).std(axis=0)
    spread = np.where(sd > 0, sd, np.inf)
    still = np.abs(second.mean(axis=0) - first.mean(axis=0)) <= drift * spread
    with np.errstate(divide="ignore", invalid="ignore"):
        kept_spread = np.where(first.std(axis=0) > 0, second.std(axis=0) / first.std(axis=0), 1.0)
    return bool(np.all(still & (kept_spread >= contraction)))


def sample_joint(model, specs, draws, priors, eps, settings, joint_seed, start_seed):
    """Joint run of one film problem with the shared parameters ``specs``, from a pilot.

    :func:`sample_blocks` with the film's records.

    Parameters
    ----------
    model : ForwardModel or FilmLayout
        Isotropic; a ForwardModel is its :class:`FilmLayout`. A film layout with more block
        coordinates than ``[a, log tau]`` (the inferred noise floor of
        :class:`bayespig.inference.roughness.NoiseFloorFilmLayout`, which has ``noise_floor_of``)
        gives records with ``noise_floor``, and its floor enters the predictive draws (and with
        an inferred incidence offset, ``incidence_offset``).
    specs : sequence of SharedParameter
    draws : numpy.ndarray
        The pilot's draws (:func:`pilot_draws`): their medians are ``theta_hat``, and the walkers
        start on them.
    priors : Priors
    eps : float
        Known relative error [-].
    settings : InferenceSettings
        Walkers are raised to what the blocks need (a few per dimension of the largest block).
    joint_seed, start_seed : numpy.random.SeedSequence
        Seed the sampler, and the walkers' start.

    Returns
    -------
    tuple
        ``(records, shared, settings, joint)``: one record per wavelength in the form of the
        per-wavelength runs (:func:`bayespig.inference.outputs._wavelength_outputs`); per spec
        ``(draws (chain, draw, size), autocorrelation times (size,))``; the settings used; the
        :class:`JointLogPosterior`.
    """
    run, used, joint = sample_blocks(model, specs, draws, settings, joint_seed, start_seed, priors, eps)
    n_wl, G = joint.n_wavelengths, joint.n_groups
    noise_floor_of = getattr(joint.layout, "noise_floor_of", None)
    theta = run.pop("theta")
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    a, tau, *physical = joint.unpack(flat)
    # per-draw predictions and pointwise log-likelihoods, in blocks of draws and stored in single
    # precision at once (as the outputs store them): on 1439 geometries x 31 bands x 4096 draws each
    # is 183 M values, 1.5 GB in double precision
    N, n_values = flat.shape[0], joint.observed.shape[1]
    model_values = np.empty((N, n_wl, n_values), dtype=STORED_DRAW_DTYPE)
    pointwise = np.empty_like(model_values)
    step = max(1, RECORD_VALUES // max(1, n_wl * n_values))
    for first in range(0, N, step):
        rows = flat[first:first + step]
        model_values[first:first + step] = joint.predict(rows)
        pointwise[first:first + step] = joint.log_likelihood(rows)
    blocks = joint.blocks_of(joint.theta_of(flat)[0])
    floor = None if noise_floor_of is None else noise_floor_of(blocks)
    flake_of = getattr(joint.layout, "flake_reflectance_of", None)
    flake = None if flake_of is None else flake_of(blocks)
    offset_of = getattr(joint.layout, "incidence_offset_of", None)
    offset = None if offset_of is None else offset_of(blocks)
    noisy = None
    if used.predictive_noise:
        rng = np.random.default_rng(run["predictive_seed"])
        noisy = model_values * (1.0 + joint.eps * rng.standard_normal(model_values.shape))
        if floor is not None:
            noisy = noisy + floor[..., None] * rng.standard_normal(model_values.shape)
        noisy = joint.layout.reading(noisy)  # an instrument that clips at 0 clips the noisy reading
    shape = (n_chains, n_draws)
    autocorr = run["autocorr_time"]
    block_index = joint.layout.flat_index  # (n_wl, k): each wavelength's coordinates in the flat vector
    records = []
    for i in range(n_wl):
        record = {
            "a": a[:, i].reshape(shape),
            "tau": tau[:, i].reshape(shape + (G,)),
            "y": model_values[:, i].reshape(shape + (-1,)),
            "log_likelihood": pointwise[:, i].reshape(shape + (-1,)),
            "lp": pointwise[:, i].sum(axis=-1, dtype=float).reshape(shape),
            "acceptance_rate": run["acceptance_rate"],
            "autocorr_time": autocorr[block_index[i]],
            "n_steps": run["n_steps"], "n_burn_in": run["n_burn_in"], "thin": run["thin"],
            "max_steps_reached": run["max_steps_reached"], "adaptation_rounds": run["adaptation_rounds"],
            "shared_acceptance": run["shared_acceptance"],
        }
        if floor is not None:
            record["noise_floor"] = floor[:, i].reshape(shape)
        if flake is not None:
            record["flake_reflectance"] = flake[:, i].reshape(shape)
        if offset is not None:
            record["incidence_offset"] = offset[:, i].reshape(shape)
        if noisy is not None:
            record["y_rep"] = noisy[:, i].reshape(shape + (-1,))
        records.append(record)
    shared_autocorr = autocorr[joint.shared_slice]
    shared = [(values.reshape(shape + (spec.size,)), shared_autocorr[part])
              for spec, values, part in zip(joint.specs, physical, joint.spec_slices)]
    return records, shared, used, joint
