"""The ensemble moves: correct stationary distribution, independent ensembles."""


import emcee
import numpy as np
import pytest

from bayespig.inference import (
    IndependentEnsemblesMove,
)

from .common import MC_Z


@pytest.mark.parametrize("kind", IndependentEnsemblesMove.KINDS)
def test_moves_sample_a_correlated_gaussian(kind):
    """Each proposal, run as 3 independent ensembles, has the target's mean and covariance."""
    mean = np.array([1.0, -2.0, 0.5])
    cov = np.array([[1.0, 0.9, 0.2], [0.9, 1.0, 0.1], [0.2, 0.1, 0.5]])
    precision = np.linalg.inv(cov)

    def log_prob(x):
        d = x - mean
        return -0.5 * np.einsum("ij,jk,ik->i", d, precision, d)

    n_ensembles, width = 3, 12
    rng = np.random.default_rng(0)
    sampler = emcee.EnsembleSampler(n_ensembles * width, 3, log_prob, vectorize=True,
                                    moves=[(IndependentEnsemblesMove(kind, n_ensembles), 1.0)])
    sampler.random_state = np.random.RandomState(1).get_state()
    sampler.run_mcmc(mean + rng.standard_normal((n_ensembles * width, 3)), 2500, progress=False)
    chain = sampler.get_chain(discard=300)
    tau = emcee.autocorr.integrated_time(chain, tol=0, quiet=True).max()
    flat = chain.reshape(-1, 3)
    n_eff = flat.shape[0] / tau
    se_mean = np.sqrt(np.diag(cov) / n_eff)
    assert np.all(np.abs(flat.mean(axis=0) - mean) < MC_Z * se_mean)
    # covariance entries: se of a sample covariance ~ sqrt((s_ii s_jj + s_ij^2) / n_eff)
    sample_cov = np.cov(flat.T)
    se_cov = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov ** 2) / n_eff)
    assert np.all(np.abs(sample_cov - cov) < MC_Z * se_cov)


def test_ensembles_do_not_mix():
    """Walkers of one ensemble never move towards another ensemble's walkers."""
    def log_prob(x):  # two far-apart modes; each ensemble starts in one
        return np.logaddexp(-0.5 * ((x - 10.0) ** 2).sum(axis=1), -0.5 * ((x + 10.0) ** 2).sum(axis=1))

    rng = np.random.default_rng(3)
    start = np.concatenate([10 + rng.standard_normal((8, 2)), -10 + rng.standard_normal((8, 2))])
    sampler = emcee.EnsembleSampler(16, 2, log_prob, vectorize=True,
                                    moves=[(IndependentEnsemblesMove("de", 2), 1.0)])
    sampler.random_state = np.random.RandomState(2).get_state()
    sampler.run_mcmc(start, 300, progress=False)
    chain = sampler.get_chain()
    assert (chain[:, :8] > 0).all() and (chain[:, 8:] < 0).all()
