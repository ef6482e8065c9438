"""Ensemble moves: several independent ensembles in one emcee sampler."""

from __future__ import annotations

import numpy as np

__all__ = ["GAUSSIAN_PROPOSAL_SCALE", "IndependentEnsemblesMove", "ensemble_halves",
           "gaussian_independence_proposal"]

#: Width of the ``"gaussian"`` independence proposal relative to the complementary walkers'
#: spread (a proposal somewhat wider than the target keeps the importance ratio bounded).
GAUSSIAN_PROPOSAL_SCALE = 1.5


def _pick(c, index):
    """``c[k, index[k, i]]`` for c of shape (G, h, d) and index of shape (G, m)."""
    return c[np.arange(c.shape[0])[:, None], index]


def ensemble_halves(n_total, n_ensembles, random, blocks=None, owner="a move"):
    """The red-blue split of every ensemble's walkers, at random (Foreman-Mackey et al. 2013).

    Parameters
    ----------
    n_total : int
        Walkers of all ensembles (contiguous blocks of equal width).
    n_ensembles : int
    random : numpy.random.RandomState
        emcee's random state.
    blocks : numpy.ndarray of int, optional
        The ensembles to split (default all).
    owner : str
        Named in the error.

    Returns
    -------
    tuple
        ``((first, second), (second, first))``: walker indices (n_blocks, width / 2) of the half
        that moves and of the half its proposals come from, for the two half-steps.
    """
    width = n_total // n_ensembles
    half = width // 2
    if width * n_ensembles != n_total or width % 2 or half < 3:
        raise RuntimeError(f"{owner} needs an even number (>= 6) of walkers per ensemble")
    blocks = np.arange(n_ensembles) if blocks is None else blocks
    order = np.argsort(random.rand(blocks.size, width), axis=1)
    order += (blocks * width)[:, None]
    return (order[:, :half], order[:, half:]), (order[:, half:], order[:, :half])


def gaussian_independence_proposal(s, c, random):
    """Gaussian independence proposals for walkers ``s`` from a Gaussian fitted to ``c``.

    ``q ~ N(mean_c, S^2 cov_c)`` with ``S`` = :data:`GAUSSIAN_PROPOSAL_SCALE`, per leading
    (batch) index: an ensemble, or an ensemble's block of coordinates.

    Parameters
    ----------
    s : numpy.ndarray
        Current points, (..., h, d).
    c : numpy.ndarray
        The complementary walkers, (..., m, d), the same leading shape.
    random : numpy.random.RandomState
        emcee's random state.

    Returns
    -------
    tuple
        ``(q, log_factor)``: proposals (..., h, d) and the Hastings factor
        ``log N(x) - log N(q)`` of the proposal (..., h) (its constants cancel).
    """
    d, m = s.shape[-1], c.shape[-2]
    mean = c.mean(axis=-2, keepdims=True)
    spread = c - mean
    cov = np.einsum("...mi,...mj->...ij", spread, spread) / (m - 1)
    ridge = 1e-12 * np.trace(cov, axis1=-2, axis2=-1) / d + 1e-300  # coincident walkers
    chol = GAUSSIAN_PROPOSAL_SCALE * np.linalg.cholesky(cov + ridge[..., None, None] * np.eye(d))
    z = random.randn(*s.shape)
    q = mean + np.einsum("...ij,...hj->...hi", chol, z)
    w = np.einsum("...ij,...hj->...hi", np.linalg.inv(chol), s - mean)  # whitened current point
    return q, 0.5 * ((z * z).sum(axis=-1) - (w * w).sum(axis=-1))


class IndependentEnsemblesMove:
    """emcee ensemble moves applied to ``n_ensembles`` disjoint, contiguous blocks of walkers.

    Each block is an ensemble on its own: the proposals of its walkers only use the other half
    of the same block (red-blue update, Foreman-Mackey et al. 2013), so the blocks are
    independent Markov chains (one arviz ``chain`` each), while every half-step evaluates the
    proposals of all blocks in one vectorised log-probability call. The proposals are emcee's,
    vectorised over walkers and blocks:

    ``"stretch"``
        :class:`emcee.moves.StretchMove` (Goodman & Weare 2010), ``a = 2``.
    ``"de"``
        :class:`emcee.moves.DEMove` (ter Braak 2006; Nelson et al. 2014):
        ``q = x + gamma (x_j - x_k)``, ``gamma = gamma0 (1 + 1e-5 N(0, 1))``,
        ``gamma0 = 2.38 / sqrt(2 d)``.
    ``"gaussian"``
        An independence proposal from a Gaussian fitted to the other half of the ensemble,
        ``q ~ N(mean_c, s^2 cov_c)`` with ``s`` = :data:`GAUSSIAN_PROPOSAL_SCALE`, and the
        Hastings factor ``log N(x) - log N(q)`` of that Gaussian: the one-component version of
        emcee's :class:`~emcee.moves.KDEMove` (a kernel density estimate of the complementary
        ensemble). It depends on the complementary walkers only, so the red-blue update keeps
        detailed balance; on compact posteriors it decorrelates in a few steps.
    ``"snooker"``
        The DE snooker update (ter Braak & Vrugt 2008): ``q = x + gamma u (u . (z1 - z2))``
        with ``u`` the unit vector from a third walker ``z`` to ``x``, ``gamma = 1.7``, and the
        Metropolis factor ``(d - 1) log(|q - z| / |x - z|)``. emcee 3.1.6's
        :class:`~emcee.moves.DESnookerMove` normalises ``u`` by ``sqrt|x - z|`` and halves the
        factor, which breaks detailed balance (fixed upstream in dfm/emcee#531, after 3.1.6),
        so it is not used.

    When several wavelengths share one sampler (a stack, see :func:`_sample_stack`), the blocks
    of one wavelength are contiguous and ``log_prob(q, member=...)`` evaluates the proposals of
    all wavelengths in one call; blocks listed in :attr:`frozen` (wavelengths whose run is
    complete) are left where they are and cost nothing.

    Parameters
    ----------
    kind : {"stretch", "de", "snooker"}
    n_ensembles : int
        Number of blocks (ensembles of all wavelengths of the sampler).
    log_prob : callable, optional
        ``log_prob(theta, member=...)`` with ``member`` the stack position of every row
        (:class:`~bayespig.likelihood.LogPosterior` of a stack); default: emcee's
        ``log_prob_fn``.
    walkers_per_member : int, optional
        Walkers per wavelength of the stack (with ``log_prob``).
    """

    KINDS = ("stretch", "de", "snooker", "gaussian")

    def __init__(self, kind, n_ensembles, log_prob=None, walkers_per_member=None):
        if kind not in self.KINDS:
            raise ValueError(f"kind must be one of {', '.join(self.KINDS)}, got {kind!r}")
        if (log_prob is None) != (walkers_per_member is None):
            raise ValueError("log_prob and walkers_per_member go together")
        self.kind = kind
        self.n_ensembles = int(n_ensembles)
        self.log_prob = log_prob
        self.walkers_per_member = walkers_per_member
        #: Boolean per block: True leaves the block's walkers unchanged (None: every block moves).
        self.frozen = None

    def tune(self, state, accepted):
        """No tuning (emcee's interface)."""

    def _proposal(self, s, c, random):
        """Proposals for walkers ``s`` (G, h, d) from their ensembles' other halves ``c``."""
        n_blocks, h, d = s.shape
        m = c.shape[1]
        if self.kind == "stretch":
            z = ((2.0 - 1.0) * random.rand(n_blocks, h) + 1.0) ** 2 / 2.0
            partner = _pick(c, random.randint(0, m, size=(n_blocks, h)))
            return partner + z[..., None] * (s - partner), (d - 1.0) * np.log(z)
        if self.kind == "de":
            first = random.randint(0, m, size=(n_blocks, h))
            second = random.randint(0, m - 1, size=(n_blocks, h))
            second += second >= first
            gamma = 2.38 / np.sqrt(2.0 * d) * (1.0 + 1e-5 * random.randn(n_blocks, h, 1))
            return s + gamma * (_pick(c, first) - _pick(c, second)), np.zeros((n_blocks, h))
        if self.kind == "gaussian":
            return gaussian_independence_proposal(s, c, random)
        order = np.argsort(random.rand(n_blocks, h, m), axis=-1)[..., :3]
        z, z1, z2 = (_pick(c, order[..., k]) for k in range(3))
        delta = s - z
        norm = np.linalg.norm(delta, axis=-1)
        degenerate = norm == 0.0  # x on top of z: no direction; the proposal is rejected
        u = delta / np.where(degenerate, 1.0, norm)[..., None]
        q = s + 1.7 * u * ((u * (z1 - z2)).sum(axis=-1))[..., None]
        with np.errstate(divide="ignore"):
            factor = (d - 1.0) * (np.log(np.linalg.norm(q - z, axis=-1)) - np.log(norm))
        factor[degenerate] = -np.inf
        return q, factor

    def propose(self, model, state):
        """One red-blue update of every walker of every ensemble (emcee's Move interface)."""
        n_total, n_dim = state.coords.shape
        random = model.random
        blocks = np.arange(self.n_ensembles)
        if self.frozen is not None:
            blocks = blocks[~np.asarray(self.frozen, dtype=bool)]
        accepted = np.zeros(n_total, dtype=bool)
        for active, other in ensemble_halves(n_total, self.n_ensembles, random, blocks, type(self).__name__):
            q, factor = self._proposal(state.coords[active], state.coords[other], random)
            q = q.reshape(-1, n_dim)
            index = active.reshape(-1)
            if self.log_prob is None:
                new_log_probs, _ = model.compute_log_prob_fn(q)
            else:
                new_log_probs = self.log_prob(q, member=index // self.walkers_per_member)
            ok = factor.reshape(-1) + new_log_probs - state.log_prob[index] > np.log(random.rand(index.size))
            state.coords[index[ok]] = q[ok]
            state.log_prob[index[ok]] = new_log_probs[ok]
            accepted[index] = ok
        return state, accepted


def _moves(settings, n_dim, n_stack=1, log_prob=None):
    """The move mixture for ``n_stack`` wavelengths of ``settings.n_ensembles`` ensembles each."""
    per_member = None if log_prob is None else settings.n_ensembles * settings.n_walkers
    return [(IndependentEnsemblesMove(kind, n_stack * settings.n_ensembles, log_prob, per_member), weight)
            for kind, weight in settings.move_mixture_for(n_dim)]
