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
known relative error ``eps``. :func:`bayespig.infer` samples it with ``substrate_sd=`` (the
same ensembles, moves, run-length rule and diagnostics as the per-wavelength runs, on the
joint vector; one vectorised table call evaluates every wavelength of every walker) and
stores the factors as the posterior variable ``r_s_factor`` over ``(chain, draw, card)``.

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

from .likelihood import Priors, multiplicative_normal_logpdf

__all__ = [
    "DEFAULT_RELATIVE_SD",
    "FACTOR_PRIOR_SDS",
    "CardFactorLogPosterior",
    "ConditionalBlocksMove",
    "card_indices",
]

#: Default prior sd of ``log f`` (about 10 % relative, paper section 3.4).
DEFAULT_RELATIVE_SD = 0.1
#: Levenberg-Marquardt damping (relative to the mean eigenvalue of J^T J) of the factors'
#: sensitivity: in a ravine the undamped Gauss-Newton step along the ravine is huge and only
#: valid for tiny factor changes. Any sensitivity gives a valid sampler (it is a change of
#: coordinates with unit Jacobian); this one only sets how well the factor moves mix.
SENSITIVITY_DAMPING = 1e-3
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


class CardFactorLogPosterior:
    """Joint log-posterior over all wavelengths with one ``r_s`` factor per card.

    Sampled in *residual* coordinates ``u = [r_a (n_wl), r_log_tau (n_wl * G), log f (n_cards)]``
    with the physical parameters ``theta_λ = theta_hat_λ + r_λ + S_λ log f``: ``theta_hat``
    is the point fit at ``f = 1`` and ``S_λ = d theta_hat_λ / d log f`` its sensitivity to
    the factors (Gauss-Newton, :meth:`_sensitivity`). The map is a translation for every
    ``f`` (unit Jacobian), so the density is the same in either coordinates; but a change
    of ``f`` at fixed ``r`` moves every wavelength's ``(a, tau)`` along with it, which is what
    the data ask for (with one value per card and wavelength a film is fitted exactly at any
    feasible ``f``). In ``u`` the wavelengths are independent given ``f`` and only weakly
    coupled to it, which :class:`ConditionalBlocksMove` uses.

    The interface of :class:`bayespig.likelihood.LogPosterior` (``lower``, ``upper``,
    ``n_dim``, ``parameter_names``, ``in_support``, call on ``u`` of shape (W, n_dim)), so
    that :func:`bayespig.inference.infer` samples it with its own run-length rule and
    diagnostics.

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

    Notes
    -----
    The prior: ``a`` uniform, ``log tau`` uniform on the boxes of :class:`Priors`; ``log f``
    normal with sd ``relative_sd``, truncated at :data:`FACTOR_PRIOR_SDS` sds and where a card
    would exceed ``r_s = 1`` at some wavelength.
    """

    def __init__(self, model, card_index, theta_hat, priors=None, eps=0.01,
                 relative_sd=DEFAULT_RELATIVE_SD, cards=None):
        priors = Priors() if priors is None else priors
        if model.g != "isotropic":
            raise ValueError("substrate factors are implemented for isotropic scattering (g fixed at 0)")
        if not (np.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be a positive number, got {eps!r}")
        if not (np.isfinite(relative_sd) and relative_sd > 0):
            raise ValueError(f"relative_sd must be a positive number, got {relative_sd!r}")
        problem = model.problem
        self.model = model
        self.card_index = np.asarray(card_index, dtype=int)
        n_reflectance = sum(f.kind == "reflectance" for f in problem.films)
        if self.card_index.shape != (n_reflectance,):
            raise ValueError(f"card_index needs one entry per reflectance film ({n_reflectance}), "
                             f"got shape {self.card_index.shape}")
        self.n_cards = int(self.card_index.max()) + 1 if n_reflectance else 0
        if self.n_cards == 0:
            raise ValueError("substrate factors need at least one reflectance film over a card")
        self.n_wavelengths = n_wl = problem.n_wavelengths
        self.n_groups = G = len(problem.groups)
        if G == 0:
            raise ValueError("substrate factors need a film that does not hide its card")
        self.evaluate = model.at_wavelength(list(range(n_wl)))
        self.observed = np.stack([problem.observed(i) for i in range(n_wl)])
        self.eps = problem.known_eps(eps)
        r_s_max = np.zeros(self.n_cards)
        k = 0
        for film in problem.films:
            if film.kind == "reflectance":
                c = self.card_index[k]
                r_s_max[c] = max(r_s_max[c], float(np.max(film.r_s)))
                k += 1
        self.relative_sd = float(relative_sd)
        self.priors = priors
        self.cards = tuple(str(c) for c in cards) if cards is not None else tuple(map(str, range(self.n_cards)))
        bound = FACTOR_PRIOR_SDS * self.relative_sd
        self.log_f_lower = np.full(self.n_cards, -bound)
        self.log_f_upper = np.minimum(bound, -np.log(np.maximum(r_s_max, 1e-12)))  # r_s f <= 1
        self.theta_lower = np.concatenate([np.full(n_wl, priors.a_range[0]),
                                           np.full(n_wl * G, np.log(priors.tau_range[0]))])
        self.theta_upper = np.concatenate([np.full(n_wl, priors.a_range[1]),
                                           np.full(n_wl * G, np.log(priors.tau_range[1]))])
        theta_hat = np.asarray(theta_hat, dtype=float).reshape(n_wl, 1 + G)
        self.theta_hat = np.concatenate([theta_hat[:, 0], theta_hat[:, 1:].reshape(-1)])
        self.theta_hat = np.clip(self.theta_hat, self.theta_lower, self.theta_upper)
        self.sensitivity = self._sensitivity()  # (n_wl * (1 + G), n_cards)
        # a box holding the support in u (for the sampler's start ball and straggler moves)
        reach = np.abs(self.sensitivity) @ np.maximum(np.abs(self.log_f_lower), np.abs(self.log_f_upper))
        self.lower = np.concatenate([self.theta_lower - self.theta_hat - reach, self.log_f_lower])
        self.upper = np.concatenate([self.theta_upper - self.theta_hat + reach, self.log_f_upper])
        wl = [f"{w:g}" for w in problem.wavelength_nm]
        self.parameter_names = tuple([f"r_a[{w}]" for w in wl]
                                     + [f"r_log_tau[{w},{g}]" for w in wl for g in problem.groups]
                                     + [f"log_r_s_factor[{c}]" for c in self.cards])
        #: Coordinates of each wavelength's block in ``u`` (n_wl, 1 + G), and of the factors.
        self.blocks = np.concatenate([np.arange(n_wl)[:, None],
                                      n_wl + np.arange(n_wl * G).reshape(n_wl, G)], axis=1)
        self.factor_slice = slice(n_wl * (1 + G), n_wl * (1 + G) + self.n_cards)

    @property
    def n_dim(self):
        """Number of parameters."""
        return self.n_wavelengths * (1 + self.n_groups) + self.n_cards

    def describe_prior(self):
        """The factors' prior as text (for the provenance)."""
        return (f"log f ~ N(0, {self.relative_sd:g}^2) per card, truncated at {FACTOR_PRIOR_SDS:g} sd "
                "and at r_s f <= 1")

    def _predict_theta(self, theta, log_f):
        """Values of every wavelength, (W, n_wl, n_values), from physical ``theta`` and ``log f``."""
        n_wl, G = self.n_wavelengths, self.n_groups
        W = theta.shape[0]
        a = theta[:, :n_wl]
        tau = np.exp(theta[:, n_wl:]).reshape(W, n_wl, G)
        member = np.tile(np.arange(n_wl), W)
        scale = np.repeat(np.exp(log_f)[:, self.card_index], n_wl, axis=0)
        values = self.evaluate(a.reshape(-1), tau.reshape(W * n_wl, G), None, scale, member=member)
        return values.reshape(W, n_wl, -1)

    def _sensitivity(self, step=1e-4):
        """``d theta_hat / d log f`` per wavelength by Gauss-Newton on the weighted residuals.

        ``S = -(J_theta^T J_theta)^+ J_theta^T J_f`` with ``J`` the derivatives of the residuals
        ``(x_obs / x_model - 1) / eps`` (central differences), damped by
        :data:`SENSITIVITY_DAMPING`; directions the data do not constrain (e.g. ``tau`` of a film
        that hides its card) get no shift.
        """
        n_wl, G, C = self.n_wavelengths, self.n_groups, self.n_cards
        base = np.concatenate([self.theta_hat, np.zeros(C)])
        inner = np.clip(base[:-C], self.theta_lower + step, self.theta_upper - step)
        base[:-C] = inner
        steps = np.eye(base.size) * step
        points = np.concatenate([base + steps, base - steps])
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            values = self._predict_theta(points[:, :-C], points[:, -C:])
            residual = (self.observed / values - 1.0) / self.eps
        derivative = (residual[:base.size] - residual[base.size:]) / (2.0 * step)  # (n_dim, n_wl, n_values)
        derivative = np.nan_to_num(derivative, nan=0.0, posinf=0.0, neginf=0.0)
        out = np.zeros((n_wl * (1 + G), C))
        for i in range(n_wl):
            rows = np.concatenate([[i], n_wl + i * G + np.arange(G)])
            J_theta = derivative[rows, i].T  # (n_values, 1 + G)
            J_f = derivative[-C:, i].T  # (n_values, C)
            normal = J_theta.T @ J_theta
            damping = SENSITIVITY_DAMPING * np.trace(normal) / normal.shape[0] + 1e-300
            out[rows] = -np.linalg.solve(normal + damping * np.eye(normal.shape[0]), J_theta.T @ J_f)
        return out

    def theta_of(self, u):
        """Physical ``[a (n_wl), log tau (n_wl * G)]`` and ``log f`` from ``u``."""
        u = np.atleast_2d(u)
        log_f = u[:, self.factor_slice]
        return self.theta_hat + u[:, :self.factor_slice.start] + log_f @ self.sensitivity.T, log_f

    def unpack(self, u):
        """``a`` (W, n_wl), ``tau`` (W, n_wl, G), factors (W, n_cards)."""
        theta, log_f = self.theta_of(u)
        n_wl = self.n_wavelengths
        return theta[:, :n_wl], np.exp(theta[:, n_wl:]).reshape(-1, n_wl, self.n_groups), np.exp(log_f)

    def in_support(self, u):
        """Boolean mask of parameter vectors inside the prior's support."""
        theta, log_f = self.theta_of(u)
        return (((theta >= self.theta_lower) & (theta <= self.theta_upper)).all(axis=1)
                & ((log_f >= self.log_f_lower) & (log_f <= self.log_f_upper)).all(axis=1))

    def predict(self, u):
        """Predicted values of every wavelength, shape (W, n_wavelengths, n_values)."""
        theta, log_f = self.theta_of(u)
        return self._predict_theta(theta, log_f)

    def log_likelihood(self, u):
        """Pointwise log-likelihood of eq. (7), shape (W, n_wavelengths, n_values)."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return multiplicative_normal_logpdf(self.observed, self.predict(u), self.eps)

    def wavelength_terms(self, u):
        """Log-likelihood of each wavelength, (W, n_wl); ``-inf`` where its ``(a, tau)`` or ``f``
        leave the prior's box."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        theta, log_f = self.theta_of(u)
        n_wl, G = self.n_wavelengths, self.n_groups
        inside = (theta >= self.theta_lower) & (theta <= self.theta_upper)
        block_ok = inside[:, :n_wl] & inside[:, n_wl:].reshape(-1, n_wl, G).all(axis=2)
        block_ok &= ((log_f >= self.log_f_lower) & (log_f <= self.log_f_upper)).all(axis=1)[:, None]
        terms = np.full((u.shape[0], n_wl), -np.inf)
        rows = block_ok.any(axis=1)
        if rows.any():
            safe = np.clip(theta[rows], self.theta_lower, self.theta_upper)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                values = multiplicative_normal_logpdf(self.observed, self._predict_theta(safe, log_f[rows]),
                                                      self.eps).sum(axis=2)
            values[~np.isfinite(values)] = -np.inf
            terms[rows] = np.where(block_ok[rows], values, -np.inf)
        return terms

    def log_prior_factors(self, u):
        """Log-density of the factors' prior (normal in ``log f``, up to a constant), (W,)."""
        log_f = np.atleast_2d(u)[:, self.factor_slice]
        return -0.5 * np.sum((log_f / self.relative_sd) ** 2, axis=1)

    def __call__(self, u, member=None):
        """Log-posterior (up to a constant), shape (W,); ``member`` is ignored (one joint problem)."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        return self.log_prior_factors(u) + self.wavelength_terms(u).sum(axis=1)


class ConditionalBlocksMove:
    """Red-blue ensemble update of :class:`CardFactorLogPosterior`, block by block.

    Within each of ``n_ensembles`` independent ensembles (one arviz chain each, as
    :class:`bayespig.inference.IndependentEnsemblesMove`), every walker of one half is updated
    from the other half in two steps:

    1. every wavelength's block ``(r_a, r_log_tau)`` by a differential-evolution proposal
       (ter Braak 2006; ``gamma = 2.38 / sqrt(2 d_block)``) from the block's values in two
       walkers of the other half, each block accepted or rejected **on its own** with its own
       likelihood term: given ``f`` the wavelengths are independent, so the joint kernel is
       the product of the blocks' Metropolis kernels;
    2. the factors ``log f`` by the same proposal in their block, accepted on the whole
       log-posterior.

    Mixing is then that of a few-parameter problem per block instead of one of
    ``n_wavelengths * (1 + G) + n_cards`` dimensions. Both proposals are symmetric and depend
    on the other half only, so detailed balance holds (Foreman-Mackey et al. 2013).

    Parameters
    ----------
    log_post : CardFactorLogPosterior
    n_ensembles : int
    """

    def __init__(self, log_post, n_ensembles):
        self.log_post = log_post
        self.n_ensembles = int(n_ensembles)
        self.frozen = None  # the interface of IndependentEnsemblesMove (one member: never frozen)

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

    def propose(self, model, state):
        """One red-blue update of every walker of every ensemble (emcee's Move interface)."""
        from .inference import ensemble_halves

        lp = self.log_post
        n_total, n_dim = state.coords.shape
        random = model.random
        accepted = np.zeros(n_total, dtype=bool)
        factor_columns = np.arange(lp.factor_slice.start, lp.factor_slice.stop)
        for active, other in ensemble_halves(n_total, self.n_ensembles, random, owner=type(self).__name__):
            s, c = state.coords[active], state.coords[other]
            index = active.reshape(-1)
            current = s.reshape(-1, n_dim)
            # 1. wavelength blocks, each accepted on its own term
            q = current.copy()
            step = self._de_step(s, c, lp.blocks, random).reshape(index.size, *lp.blocks.shape)
            q[:, lp.blocks] += step
            old_terms, new_terms = lp.wavelength_terms(current), lp.wavelength_terms(q)
            with np.errstate(invalid="ignore"):
                take = new_terms - old_terms > np.log(random.rand(*new_terms.shape))
            moved = current.copy()
            moved_cols = np.where(take[..., None], q[:, lp.blocks], current[:, lp.blocks])
            moved[:, lp.blocks] = moved_cols
            terms = np.where(take, new_terms, old_terms)
            # 2. the factors, on the whole log-posterior
            q = moved.copy()
            q[:, factor_columns] += self._de_step(s, c, factor_columns[None], random).reshape(index.size, -1)
            before = lp.log_prior_factors(moved) + terms.sum(axis=1)
            after = lp(q)
            with np.errstate(invalid="ignore"):
                ok = after - before > np.log(random.rand(index.size))
            moved[ok] = q[ok]
            state.coords[index] = moved
            state.log_prob[index] = np.where(ok, after, before)
            accepted[index] = ok | take.any(axis=1)
        return state, accepted
