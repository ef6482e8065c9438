"""Substrate albedo as a nuisance parameter: one factor per card, shared by all wavelengths.

The albedo ``r_s`` a film sees from inside the binder is converted from the bare card measured
in air (paper section 3.4, :func:`bayespig.physics.substrate.substrate_albedo_from_air`); the
paper expects the true value to differ by up to ~10 % (relative). Fixing it can make a film
unfittable (a white film over a white card brighter than any non-absorbing layer over the
converted ``r_s``) or bias ``a`` and ``tau``. Here each card ``c`` gets a factor ``f_c``,

    r_s(λ) = f_c * r_s,card(λ),    log f_c ~ N(0, relative_sd^2),

one per card and film set, the same at every wavelength (so that it stays identifiable: a
per-wavelength factor would trade off against ``a`` and ``tau`` wavelength by wavelength). The
posterior is joint over all wavelengths: parameters
``[a_λ (n_wl), log tau_λ,group (n_wl * G), log f_card (n_cards)]`` with the priors of
:class:`bayespig.likelihood.Priors` on ``a`` and ``tau`` and the likelihood of eq. (7) with a
known relative error ``eps``. It is sampled with emcee (differential-evolution moves, walkers
started around the point fit at ``f = 1``).

Identifiability: a factor is learned from the data only when the films over that card have
more values per wavelength than parameters (multi-angle instruments, several film groups of one
pigment) or when the fixed card makes the model infeasible; with one sphere value per card and
wavelength (method 4 on an 8°/d instrument) every ``f`` within the feasible range fits exactly
and the factor's posterior is its prior truncated by feasibility. Both are reported honestly by
:func:`substrate_factor_posterior`.

Wiring into :func:`bayespig.inference.infer` (not done here): ``infer`` samples each wavelength
independently; a card factor couples them. What it needs is (1) the card of every reflectance
film (``MeasurementSet.sample(name).substrate``) -> an index, as built by :func:`card_indices`;
(2) the extra coordinates ``log f`` appended after ``[a, log tau.., (g), (log eps)]`` of every
wavelength and a Gaussian prior term; (3) ``WavelengthModel.__call__(..., r_s_scale=f[:, card])``
(the keyword added for this purpose); and (4) either a joint sampler over all wavelengths (as
here) or a Gibbs step alternating per-wavelength updates with a factor update.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), eq. (3), eq. (7), section 3.4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .likelihood import ForwardModel, Priors, Problem

__all__ = [
    "DEFAULT_RELATIVE_SD",
    "SubstrateNuisancePosterior",
    "SubstrateNuisanceResult",
    "card_indices",
    "substrate_factor_posterior",
]

#: Default prior sd of ``log f`` (about 10 % relative, paper section 3.4).
DEFAULT_RELATIVE_SD = 0.1
_LOG_2PI = np.log(2.0 * np.pi)


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


class SubstrateNuisancePosterior:
    """Joint log-posterior over all wavelengths with one ``r_s`` factor per card.

    Parameters
    ----------
    model : ForwardModel
    card_index : array_like of int
        Card of every reflectance film (problem order), e.g. from :func:`card_indices`.
    priors : Priors, optional
        Ranges of ``a`` and ``tau`` (default :class:`~bayespig.likelihood.Priors`).
    eps : float
        Known relative measurement error of eq. (7) [-].
    relative_sd : float
        Prior sd of ``log f`` [-].

    Notes
    -----
    Parameter vector (per walker): ``a`` at each wavelength, then ``log tau`` (wavelength-major,
    group-minor), then ``log f`` per card. Called with ``theta`` of shape (W, n_dim).
    """

    def __init__(self, model, card_index, priors=None, eps=0.01, relative_sd=DEFAULT_RELATIVE_SD):
        priors = Priors() if priors is None else priors
        if not (np.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be a positive number, got {eps!r}")
        if not (np.isfinite(relative_sd) and relative_sd > 0):
            raise ValueError(f"relative_sd must be a positive number, got {relative_sd!r}")
        problem = model.problem
        self.card_index = np.asarray(card_index, dtype=int)
        n_reflectance = sum(f.kind == "reflectance" for f in problem.films)
        if self.card_index.shape != (n_reflectance,):
            raise ValueError(f"card_index needs one entry per reflectance film ({n_reflectance}), "
                             f"got shape {self.card_index.shape}")
        self.n_cards = int(self.card_index.max()) + 1 if n_reflectance else 0
        self.n_wavelengths = problem.n_wavelengths
        self.n_groups = len(problem.groups)
        self.evaluators = [model.at_wavelength(i) for i in range(self.n_wavelengths)]
        self.observed = [problem.observed(i) for i in range(self.n_wavelengths)]
        self.r_s_max = np.zeros(self.n_cards)
        k = 0
        for film in problem.films:
            if film.kind == "reflectance":
                c = self.card_index[k]
                self.r_s_max[c] = max(self.r_s_max[c], float(np.max(film.r_s)))
                k += 1
        self.eps = float(eps)
        self.relative_sd = float(relative_sd)
        self.priors = priors
        n_wl, G = self.n_wavelengths, self.n_groups
        self.lower = np.concatenate([np.full(n_wl, priors.a_range[0]),
                                     np.full(n_wl * G, np.log(priors.tau_range[0])),
                                     np.full(self.n_cards, -np.inf)])
        self.upper = np.concatenate([np.full(n_wl, priors.a_range[1]),
                                     np.full(n_wl * G, np.log(priors.tau_range[1])),
                                     -np.log(np.maximum(self.r_s_max, 1e-12))])  # r_s f <= 1

    @property
    def n_dim(self):
        """Number of parameters."""
        return self.n_wavelengths * (1 + self.n_groups) + self.n_cards

    def pack(self, a, tau, factors):
        """Parameter vectors from ``a`` (W, n_wl), ``tau`` (W, n_wl, G) and factors (W, n_cards)."""
        a = np.atleast_2d(a)
        W = a.shape[0]
        return np.concatenate([a, np.log(np.asarray(tau)).reshape(W, -1),
                               np.log(np.atleast_2d(factors))], axis=1)

    def unpack(self, theta):
        """``a`` (W, n_wl), ``tau`` (W, n_wl, G), factors (W, n_cards)."""
        theta = np.atleast_2d(theta)
        n_wl, G = self.n_wavelengths, self.n_groups
        a = theta[:, :n_wl]
        tau = np.exp(theta[:, n_wl:n_wl * (1 + G)]).reshape(-1, n_wl, G)
        return a, tau, np.exp(theta[:, n_wl * (1 + G):])

    def __call__(self, theta):
        """Log-posterior (up to a constant), shape (W,)."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        out = np.full(theta.shape[0], -np.inf)
        ok = ((theta >= self.lower) & (theta <= self.upper)).all(axis=1)
        if not ok.any():
            return out
        a, tau, factors = self.unpack(theta[ok])
        log_f = np.log(factors)
        value = -0.5 * np.sum((log_f / self.relative_sd) ** 2, axis=1)
        scale = factors[:, self.card_index]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for i, evaluate in enumerate(self.evaluators):
                model = evaluate(a[:, i], tau[:, i, :], None, scale)
                z = (self.observed[i] / model - 1.0) / self.eps
                value += -0.5 * np.sum(z * z, axis=1) - np.sum(np.log(model), axis=1)
        value[~np.isfinite(value)] = -np.inf
        out[ok] = value
        return out


@dataclass(frozen=True)
class SubstrateNuisanceResult:
    """Samples of the joint posterior with card factors.

    Attributes
    ----------
    cards : tuple of str
    factors : numpy.ndarray
        Shape (n_samples, n_cards): ``f`` per card [-].
    a : numpy.ndarray
        Shape (n_samples, n_wavelengths).
    tau : numpy.ndarray
        Shape (n_samples, n_wavelengths, n_groups).
    wavelength_nm : numpy.ndarray
    settings : dict
        Seed, walkers, steps, burn-in, eps, relative_sd, acceptance fraction, emcee version.
    """

    cards: tuple
    factors: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    wavelength_nm: np.ndarray
    settings: dict

    def summary(self, probability=0.9):
        """Card -> (median, lower, upper) of the central ``probability`` interval of ``f``."""
        q = [0.5, (1 - probability) / 2, (1 + probability) / 2]
        return {card: tuple(float(v) for v in np.quantile(self.factors[:, k], q))
                for k, card in enumerate(self.cards)}


def substrate_factor_posterior(measurements, *, method="auto", eps=0.01, relative_sd=DEFAULT_RELATIVE_SD,
                               priors=None, seed=0, n_walkers=None, n_steps=3000, burn_in=None,
                               thin=10, tables=None):
    """Sample the posterior of ``a``, ``tau`` and one substrate factor per card (all wavelengths jointly).

    Parameters
    ----------
    measurements : MeasurementSet
    method : str
        Samples used (:meth:`bayespig.likelihood.Problem.from_measurements`).
    eps : float
        Known relative measurement error of eq. (7) [-].
    relative_sd : float
        Prior sd of ``log f`` [-] (default 0.1, ~10 %).
    priors : Priors, optional
        Ranges of ``a`` and ``tau`` (default :class:`~bayespig.likelihood.Priors`).
    seed : int
        Seeds the starting jitter and emcee's random state (``numpy.random.default_rng``).
    n_walkers : int, optional
        Default ``max(4 * n_dim, 32)``, even.
    n_steps : int
        Steps per walker.
    burn_in : int, optional
        Steps discarded (default half of ``n_steps``).
    thin : int
        Keep every ``thin``-th step.
    tables : dict, optional
        Instrument -> isotropic look-up table.

    Returns
    -------
    SubstrateNuisanceResult
    """
    import emcee

    from .fit import fit_problem

    priors = Priors() if priors is None else priors
    problem = Problem.from_measurements(measurements, method)
    model = ForwardModel(problem, "isotropic", dict(tables or {}))
    cards, index = card_indices(measurements, problem)
    log_post = SubstrateNuisancePosterior(model, index, priors, eps, relative_sd)
    fit = fit_problem(problem, tables=model.tables, warn=False)
    a0 = np.clip(fit.a, priors.a_range[0] + 1e-4, priors.a_range[1] - 1e-4)
    tau0 = np.clip(fit.tau, priors.tau_range[0] * 1.01, priors.tau_range[1] / 1.01)
    theta0 = log_post.pack(a0[None], tau0[None], np.ones((1, log_post.n_cards)))[0]
    n_dim = log_post.n_dim
    n_walkers = n_walkers or max(4 * n_dim, 32)
    n_walkers += n_walkers % 2
    rng = np.random.default_rng(seed)
    start = []
    while len(start) < n_walkers:
        trial = theta0 + rng.normal(0.0, 1e-3, (n_walkers, n_dim))
        trial[:, -log_post.n_cards:] = rng.normal(0.0, 0.2 * relative_sd, (n_walkers, log_post.n_cards))
        start.extend(trial[np.isfinite(log_post(trial))])
    start = np.array(start[:n_walkers])
    sampler = emcee.EnsembleSampler(
        n_walkers, n_dim, log_post, vectorize=True,
        moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)],
    )
    sampler.random_state = np.random.RandomState(rng.integers(2**32 - 1)).get_state()
    sampler.run_mcmc(start, n_steps, progress=False)
    burn_in = n_steps // 2 if burn_in is None else int(burn_in)
    chain = sampler.get_chain(discard=burn_in, thin=thin, flat=True)
    a, tau, factors = log_post.unpack(chain)
    settings = {"seed": seed, "n_walkers": n_walkers, "n_steps": n_steps, "burn_in": burn_in, "thin": thin,
                "eps": eps, "relative_sd": relative_sd, "method": problem.method,
                "acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
                "emcee": emcee.__version__, "priors": priors.describe()}
    return SubstrateNuisanceResult(cards, factors, a, tau, np.asarray(problem.wavelength_nm), settings)
