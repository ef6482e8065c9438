"""Substrate albedo as a nuisance parameter: one factor per card, shared by all wavelengths.

The albedo ``r_s`` a film sees from inside the binder is converted from the bare card measured
in air (paper section 3.4, :func:`bayespig.physics.substrate.substrate_albedo_from_air`); the
paper expects the true value to differ by up to ~10 % (relative). Fixing it can make a film
unfittable (a white film over a white card brighter than any non-absorbing layer over the
converted ``r_s``) or bias ``a`` and ``tau``. Here each card ``c`` gets a factor ``f_c``,

    r_s(λ) = f_c * r_s,card(λ),    log f_c ~ N(0, relative_sd^2),

one per card, the same at every wavelength (so that it stays identifiable: a per-wavelength
factor would trade off against ``a`` and ``tau`` wavelength by wavelength). The factor couples
the wavelengths, so the posterior is joint over all of them: parameters
``[a_λ (n_wl), log tau_λ,group (n_wl * G), log f_card (n_cards)]`` with the priors of
:class:`bayespig.likelihood.Priors` on ``a`` and ``tau`` and the likelihood of eq. (7) with a
known relative error ``eps``. The factors are one spec (:class:`CardFactors`) of the joint
machinery for parameters shared over wavelengths (:mod:`bayespig.inference.shared`: residual
coordinates, block-wise moves, a pilot start); :func:`bayespig.infer` samples it with
``substrate_sd=`` (the same ensembles, run-length rule and diagnostics as the per-wavelength
runs, on the joint vector; one vectorised table call evaluates every wavelength of every
walker) and stores the factors as the posterior variable ``r_s_factor`` over
``(chain, draw, card)``. A pigment library's build samples the same spec over the cards of all
films of a stage (:meth:`CardFactors.over_cards`, :func:`bayespig.library.build.card_factor_spec`).

Identifiability: a factor is learned from the data only when the films over that card have
more values per wavelength than parameters (multi-angle instruments, several film groups of one
pigment) or when the fixed card makes the model infeasible; with one sphere value per card and
wavelength (method 4 on an 8°/d instrument) every ``f`` within the feasible range fits exactly
and the factor's posterior is its prior truncated by feasibility. The posterior of ``a`` and
``tau`` is then wider than with a fixed card: the card's uncertainty is propagated.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), eq. (3), eq. (7), section 3.4.
"""

from __future__ import annotations

import numpy as np

from .shared import BlockwiseMove, JointLogPosterior, SharedParameter

__all__ = [
    "DEFAULT_RELATIVE_SD",
    "FACTOR_PRIOR_SDS",
    "CardFactorLogPosterior",
    "CardFactors",
    "ConditionalBlocksMove",
    "card_indices",
]

#: Default prior sd of ``log f`` (about 10 % relative, paper section 3.4).
DEFAULT_RELATIVE_SD = 0.1
#: The log-normal prior of a factor is truncated at this many sds (a bounded box for the
#: sampler's start and moves; the mass beyond is 6e-7).
FACTOR_PRIOR_SDS = 5.0


def card_indices(measurements, problem):
    """The card of every reflectance film of ``problem``: names and an index per film.

    Films on the same substrate sample (or the same named/numeric substrate) share a card.

    Parameters
    ----------
    measurements : MeasurementSet
    problem : Problem
        Built from ``measurements``.

    Returns
    -------
    tuple
        ``(cards, index)``: card names (tuple of str) and, per reflectance film in problem
        order, the index of its card (numpy int array). Opaque films get a card too (their
        ``r_s`` is 0, so the factor has no effect on them).
    """
    cards, index = [], []
    for film in problem.films:
        if film.kind != "reflectance":
            continue
        sample = measurements.sample(film.name)
        card = "hidden" if sample.opaque or sample.substrate is None else str(sample.substrate)
        if card not in cards:
            cards.append(card)
        index.append(cards.index(card))
    return tuple(cards), np.array(index, dtype=int)


class CardFactors(SharedParameter):
    """One ``r_s`` factor per card, shared by all wavelengths: the spec of :mod:`bayespig.inference.shared`.

    Sampled coordinate ``log f`` per card, prior ``N(0, relative_sd^2)`` truncated at
    :data:`FACTOR_PRIOR_SDS` sds and where a card would exceed ``r_s = 1`` at some wavelength;
    it enters the forward model as the factor ``r_s_scale`` on every reflectance film's
    substrate albedo (:class:`bayespig.likelihood.WavelengthModel`).

    Parameters
    ----------
    problem : Problem
    card_index : array_like of int
        Card of every reflectance film (problem order), e.g. from :func:`card_indices`.
    relative_sd : float
        Prior sd of ``log f`` [-].
    cards : sequence of str, optional
        Card names (the labels; default ``"0"``, ``"1"``, ...).
    """

    title = "substrate factors"
    variable = "r_s_factor"
    dimension = "card"
    long_name = "factor on the card's albedo seen from the binder, r_s / r_s,card"
    units = "1"
    coordinate_name = "log_r_s_factor"
    attribute = "substrate_factors"
    prior_scale = "log"  # log f is sampled, its prior normal in log f

    def __init__(self, problem, card_index, relative_sd=DEFAULT_RELATIVE_SD, cards=None):
        if not (np.isfinite(relative_sd) and relative_sd > 0):
            raise ValueError(f"relative_sd must be a positive number, got {relative_sd!r}")
        card_index = np.asarray(card_index, dtype=int)
        n_reflectance = sum(f.kind == "reflectance" for f in problem.films)
        if card_index.shape != (n_reflectance,):
            raise ValueError(f"card_index needs one entry per reflectance film ({n_reflectance}), "
                             f"got shape {card_index.shape}")
        n_cards = int(card_index.max()) + 1 if n_reflectance else 0
        if n_cards == 0:
            raise ValueError("substrate factors need at least one reflectance film over a card")
        if not problem.groups:
            raise ValueError("substrate factors need a film that does not hide its card")
        r_s_max = np.zeros(n_cards)
        k = 0
        for film in problem.films:
            if film.kind == "reflectance":
                c = card_index[k]
                r_s_max[c] = max(r_s_max[c], float(np.max(film.r_s)))
                k += 1
        self._set_cards(card_index, r_s_max, relative_sd, cards)

    @classmethod
    def over_cards(cls, card_index, r_s_max, relative_sd=DEFAULT_RELATIVE_SD, cards=None):
        """The factors of any set of cards, without a :class:`~bayespig.likelihood.Problem`.

        For a model whose reflectance films span several measurement sets (the films of a
        pigment library's stage, :mod:`bayespig.library.build`: one factor per card and film,
        every film's reflectance films concatenated in the model input ``r_s_scale``).

        Parameters
        ----------
        card_index : array_like of int
            Card of every reflectance film of the model, in the order of ``r_s_scale``'s
            columns; ``-1`` for a film whose card gets no factor (an opaque film: ``r_s = 0``),
            whose column is then 1.
        r_s_max : array_like of float
            Largest albedo seen from the binder of each card over the wavelengths [-], (n_cards,)
            (the prior is truncated at ``f r_s_max <= 1``).
        relative_sd : float
            Prior sd of ``log f`` [-].
        cards : sequence of str, optional
            Card names (the labels; default ``"0"``, ``"1"``, ...).

        Raises
        ------
        ValueError
            Naming the argument: ``relative_sd`` not a positive number, no card, a card
            index outside ``-1 .. n_cards - 1``, ``r_s_max`` or ``cards`` not one per card.
        """
        if not (np.isfinite(relative_sd) and relative_sd > 0):
            raise ValueError(f"relative_sd must be a positive number, got {relative_sd!r}")
        card_index = np.asarray(card_index, dtype=int)
        r_s_max = np.asarray(r_s_max, dtype=float)
        if r_s_max.ndim != 1 or r_s_max.size == 0:
            raise ValueError(f"r_s_max needs one value per card (at least one), got shape {r_s_max.shape}")
        if card_index.ndim != 1 or ((card_index < -1) | (card_index >= r_s_max.size)).any():
            raise ValueError(f"card_index must be card numbers 0..{r_s_max.size - 1} (or -1: no factor), "
                             f"got {card_index.tolist()}")
        if cards is not None and len(cards) != r_s_max.size:
            raise ValueError(f"cards must name every card ({r_s_max.size}), got {len(cards)}")
        self = cls.__new__(cls)
        self._set_cards(card_index, r_s_max, relative_sd, cards)
        return self

    def _set_cards(self, card_index, r_s_max, relative_sd, cards):
        """The attributes of the spec from the cards of the reflectance films and their largest albedo."""
        self.card_index = card_index
        self.n_cards = r_s_max.size
        self.relative_sd = float(relative_sd)
        self.cards = self.labels = (tuple(str(c) for c in cards) if cards is not None
                                    else tuple(map(str, range(self.n_cards))))
        bound = FACTOR_PRIOR_SDS * self.relative_sd
        self.lower = np.full(self.n_cards, -bound)
        self.upper = np.minimum(bound, -np.log(np.maximum(r_s_max, 1e-12)))  # r_s f <= 1
        self.nominal = np.zeros(self.n_cards)
        self.start_sd = np.full(self.n_cards, 0.01 * self.relative_sd)
        #: reflectance films without a factor (index -1): their column of r_s_scale is 1
        self._unscaled = None if (card_index >= 0).all() else card_index < 0

    def log_prior(self, x):
        """Normal in ``log f`` (up to a constant), (W,)."""
        return -0.5 * np.sum((x / self.relative_sd) ** 2, axis=1)

    def physical(self, x):
        """The factors ``f = exp(log f)``."""
        return np.exp(x)

    def model_inputs(self, x):
        """``r_s_scale``: every reflectance film's factor, (W, n_reflectance_films)."""
        if self._unscaled is None:
            return {"r_s_scale": np.exp(x)[:, self.card_index]}
        scale = np.exp(x)[:, np.maximum(self.card_index, 0)]
        scale[:, self._unscaled] = 1.0
        return {"r_s_scale": scale}

    def describe_prior(self):
        """The factors' prior as text (for the provenance)."""
        return (f"log f ~ N(0, {self.relative_sd:g}^2) per card, truncated at {FACTOR_PRIOR_SDS:g} sd "
                "and at r_s f <= 1")

    def describe(self):
        """Relative sd, cards and prior (the ``substrate_factors`` attribute)."""
        return {"relative_sd": self.relative_sd, "cards": list(self.cards), "prior": self.describe_prior()}


class CardFactorLogPosterior(JointLogPosterior):
    """Joint log-posterior over all wavelengths with one ``r_s`` factor per card.

    :class:`bayespig.inference.shared.JointLogPosterior` with the one spec :class:`CardFactors`:
    sampled in residual coordinates ``u = [r_a (n_wl), r_log_tau (n_wl * G), log f (n_cards)]``
    with the physical parameters ``theta_λ = theta_hat_λ + r_λ + S_λ log f``.

    Parameters
    ----------
    model : ForwardModel
        Isotropic.
    card_index : array_like of int
        Card of every reflectance film (problem order), e.g. from :func:`card_indices`.
    theta_hat : numpy.ndarray
        Point fit per wavelength ``[a, log tau_1..G]``, shape (n_wavelengths, 1 + G).
    priors : Priors, optional
        Ranges of ``a`` and ``tau`` (default :class:`~bayespig.likelihood.Priors`).
    eps : float
        Known relative measurement error of eq. (7) for films without their own [-].
    relative_sd : float
        Prior sd of ``log f`` [-].
    cards : sequence of str, optional
        Card names (for ``parameter_names``).
    """

    def __init__(self, model, card_index, theta_hat, priors=None, eps=0.01,
                 relative_sd=DEFAULT_RELATIVE_SD, cards=None):
        if model.g != "isotropic":
            raise ValueError("substrate factors are implemented for isotropic scattering (g fixed at 0)")
        if not (np.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be a positive number, got {eps!r}")
        spec = CardFactors(model.problem, card_index, relative_sd, cards)
        super().__init__(model, theta_hat, [spec], priors, eps)
        self.spec = spec
        self.card_index, self.n_cards, self.cards, self.relative_sd = (
            spec.card_index, spec.n_cards, spec.cards, spec.relative_sd)
        self.log_f_lower, self.log_f_upper = spec.lower, spec.upper
        self.factor_slice = self.shared_slice
        self.describe_prior = spec.describe_prior

    def log_prior_factors(self, u):
        """Log-density of the factors' prior (normal in ``log f``, up to a constant), (W,)."""
        return self.log_prior_shared(u)


#: The block-wise move of the joint run (its name when the card factors were its only use).
ConditionalBlocksMove = BlockwiseMove
