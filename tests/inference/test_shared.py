"""The joint machinery for parameters shared over wavelengths, with more than one spec."""

import arviz as az
import emcee
import numpy as np
import pytest
from scipy import stats

from bayespig.data import simulate
from bayespig.inference import InferenceSettings, infer_problem
from bayespig.inference.card_factors import CardFactorLogPosterior, CardFactors, card_indices
from bayespig.inference.shared import (MAX_ADAPTATION_ROUNDS, JointLogPosterior, SharedParameter,
                                      adaptation_settled)
from bayespig.likelihood import ForwardModel, Priors, Problem

from .common import MC_Z

EPS = 0.01
QUICK = InferenceSettings(target_ess=400.0, draws_per_chain=512, max_steps=20000)
#: The unseen parameter's prior: normal with this sd, truncated at TRUNCATION sds.
UNSEEN_SD, TRUNCATION = 0.5, 3.0


class _Unseen(SharedParameter):
    """A shared parameter no measured value depends on: its posterior is its prior."""

    title = "unseen parameter"
    variable = "unseen"
    dimension = "unseen_index"
    coordinate_name = "unseen"
    long_name = "a parameter no value depends on"

    def __init__(self):
        self.labels = ("only",)
        self.lower = np.array([-TRUNCATION * UNSEEN_SD])
        self.upper = np.array([TRUNCATION * UNSEEN_SD])
        self.nominal = np.zeros(1)
        self.start_sd = np.array([0.01 * UNSEEN_SD])

    def log_prior(self, x):
        return -0.5 * np.sum((x / UNSEEN_SD) ** 2, axis=1)

    def physical(self, x):
        return x

    def model_inputs(self, x):
        return {}

    def describe(self):
        return {"sd": UNSEEN_SD}


@pytest.fixture(scope="module")
def film():
    ms = simulate(a=np.array([0.3, 0.1]), tau=np.array([1.0, 1.5]), design="method4", instrument="multi-angle-45",
                  wavelengths=[450.0, 650.0], eps=EPS, seed=4)
    problem = Problem.from_measurements(ms, "method4")
    return ms, problem, ForwardModel(problem, "isotropic", {})


def test_two_specs_add_their_priors_and_concatenate_their_coordinates(film):
    """[card factors, unseen]: the density is the card factors' one plus the unseen prior,
    the unseen coordinate comes last and nothing depends on it."""
    ms, problem, model = film
    cards, index = card_indices(ms, problem)
    theta_hat = np.array([[0.3, 0.0], [0.1, 0.4]])
    cards_only = CardFactorLogPosterior(model, index, theta_hat, Priors(), EPS, 0.1, cards)
    both = JointLogPosterior(model, theta_hat, [CardFactors(problem, index, 0.1, cards), _Unseen()], Priors(), EPS)
    assert both.n_dim == cards_only.n_dim + 1
    assert both.parameter_names == cards_only.parameter_names + ("unseen[only]",)
    np.testing.assert_array_equal(both.sensitivity[:, -1], 0.0)
    rng = np.random.default_rng(1)
    u = np.concatenate([rng.normal(0, 0.01, (6, cards_only.n_dim)), rng.normal(0, UNSEEN_SD, (6, 1))], axis=1)
    u[:, -1] = np.clip(u[:, -1], -1.4, 1.4)
    expected = cards_only(u[:, :-1]) - 0.5 * (u[:, -1] / UNSEEN_SD) ** 2
    np.testing.assert_allclose(both(u), expected, rtol=1e-12)
    outside = u[:1].copy()
    outside[0, -1] = 1.01 * TRUNCATION * UNSEEN_SD
    assert both(outside)[0] == -np.inf
    a, tau, factors, unseen = both.unpack(u)
    for mine, reference in zip((a, tau, factors), cards_only.unpack(u[:, :-1])):
        np.testing.assert_allclose(mine, reference, rtol=1e-12)
    np.testing.assert_array_equal(unseen, u[:, -1:])


def test_the_joint_sampler_runs_any_list_of_specs(film):
    """infer_problem(shared=[card factors, unseen]): one joint run; the unseen parameter's
    posterior is its truncated normal prior, stored with its attributes like r_s_factor."""
    ms, problem, model = film
    cards, index = card_indices(ms, problem)
    idata = infer_problem(problem, seed=2, eps=EPS, progress=False, settings=QUICK, tables=model.tables,
                          shared=[CardFactors(problem, index, 0.1, cards), _Unseen()])
    post = idata.posterior
    assert post["unseen"].dims == ("chain", "draw", "unseen_index")
    assert post["unseen"].attrs["long_name"] == "a parameter no value depends on"
    assert post["r_s_factor"].dims == ("chain", "draw", "card")
    assert idata.sample_stats["unseen_autocorr_time"].dims == ("unseen_index",)
    # how many adaptation runs preceded the run proper, stored with the run
    rounds = idata.sample_stats["adaptation_rounds"].values
    assert rounds.shape == (problem.n_wavelengths,) and len(set(rounds)) == 1
    assert 1 <= rounds[0] <= MAX_ADAPTATION_ROUNDS
    # the share of shared-block proposals accepted: one value for the joint run, a proper share
    shared_acceptance = idata.sample_stats["shared_acceptance"].values
    assert len(set(shared_acceptance)) == 1 and 0.0 < shared_acceptance[0] < 1.0
    draws = post["unseen"].values[..., 0]
    ess = float(az.ess(draws))
    prior = stats.truncnorm(-TRUNCATION, TRUNCATION, scale=UNSEEN_SD)
    assert abs(draws.mean() - prior.mean()) < MC_Z * prior.std() / np.sqrt(ess)
    # sd of a sample sd ~ sd / sqrt(2 n_eff)
    assert abs(draws.std() / prior.std() - 1.0) < MC_Z / np.sqrt(2.0 * ess)
    assert float(az.rhat(draws)) < 1.01


def test_residual_coordinates_invert_and_the_regression_recovers_a_linear_dependence(film):
    """u_of inverts theta_of; over points with theta exactly linear in phi the regression's
    centre and sensitivity are that line, and r is then zero."""
    ms, problem, model = film
    cards, index = card_indices(ms, problem)
    post = CardFactorLogPosterior(model, index, np.array([[0.3, 0.0], [0.1, 0.4]]), Priors(), EPS, 0.1, cards)
    rng = np.random.default_rng(7)
    u = np.concatenate([rng.normal(0, 0.01, (20, 4)), rng.normal(0, 0.05, (20, 2))], axis=1)
    np.testing.assert_allclose(post.u_of(*post.theta_of(u)), u, atol=1e-14)
    centre = np.array([0.25, 0.05, 0.12, 0.3])  # [a (2 wl), log tau (2 wl)]
    slope = rng.normal(0, 1.0, (4, 2))
    phi = rng.normal(0, 0.05, (50, 2))
    points = post.u_of(centre + phi @ slope.T, phi)
    theta_hat, sensitivity = post.regression(points)
    np.testing.assert_allclose(theta_hat, [[0.25, 0.12], [0.05, 0.3]], atol=1e-12)
    np.testing.assert_allclose(sensitivity, slope, atol=1e-10)
    refit = JointLogPosterior(model, theta_hat, post.specs, Priors(), EPS, sensitivity=sensitivity)
    np.testing.assert_allclose(refit.u_of(centre + phi @ slope.T, phi)[:, :4], 0.0, atol=1e-12)
    with pytest.raises(ValueError, match=r"sensitivity must have shape \(4, 2\)"):
        JointLogPosterior(model, theta_hat, post.specs, Priors(), EPS, sensitivity=sensitivity[:2])


def test_an_adaptation_run_counts_as_settled_only_without_drift_or_contraction():
    """adaptation_settled: stationary draws settle; a mean that travels by 1 sd between the
    halves, or an ensemble whose spread halves, does not."""
    rng = np.random.default_rng(3)
    shape = (4, 16, 40)  # ensembles, walkers, steps
    block = rng.normal(0.0, 1.0, shape + (3,))
    stationary = np.concatenate([block, rng.normal(0.0, 1.0, shape + (2,))], axis=-1)
    phi = slice(3, 5)
    assert adaptation_settled(stationary, phi)
    travelling = stationary.copy()
    travelling[..., 3] += np.linspace(0.0, 3.0, shape[2])  # ~1 sd of the whole run between the halves' means
    assert not adaptation_settled(travelling, phi)
    shrinking = stationary.copy()
    shrinking[:, :, shape[2] // 2:, 4] *= 0.5
    assert not adaptation_settled(shrinking, phi)
    # the blocks' own coordinates do not count
    moving_block = stationary.copy()
    moving_block[..., 0] += np.linspace(0.0, 30.0, shape[2])
    assert adaptation_settled(moving_block, phi)


def test_the_dense_check_completes_a_many_parameter_run_the_stored_draws_cannot():
    """94 parameters of independent draws (a Revigo film's joint run has 31 * 3 + 2): on the
    128 stored draws per chain R-hat <= 1.01 and ESS >= 400 fail by chance for some parameter at
    every check (so such runs went to max_steps); checked on the thinned chain they pass."""
    from bayespig.inference.sampler import _run_verdict

    settings = InferenceSettings(target_ess=400, draws_per_chain=128)
    steps = 2000
    chain = np.random.default_rng(0).standard_normal((steps, settings.n_ensembles * settings.n_walkers, 94))
    log_prob = -0.5 * (chain ** 2).sum(axis=2)
    assert isinstance(_run_verdict(chain, log_prob, settings, steps), int)  # not complete: check again later
    done = _run_verdict(chain, log_prob, settings, steps, dense_check=True)
    assert isinstance(done, dict) and not done["max_steps_reached"]
    assert done["theta"].shape == (settings.n_ensembles, 128, 94)


def test_the_shared_coordinates_stored_draws_must_pass_too():
    """With ``stored_check``, a joint run whose thinned chain passes is still not complete while
    a shared coordinate's stored draws fail (here one ensemble offset by 0.5 sd in it: R-hat of
    the stored draws ~1.03); without the offset it completes at the same step."""
    from bayespig.inference.sampler import _run_verdict

    settings = InferenceSettings(target_ess=400, draws_per_chain=128)
    steps, width = 2000, settings.n_walkers
    chain = np.random.default_rng(1).standard_normal((steps, settings.n_ensembles * width, 6))
    log_prob = -0.5 * (chain ** 2).sum(axis=2)
    assert isinstance(_run_verdict(chain, log_prob, settings, steps, dense_check=True, stored_check=slice(5, 6)), dict)
    offset = chain.copy()
    offset[-steps // 4:, :width, 5] += 0.5  # the last quarter of one ensemble: the stored draws see it
    verdict = _run_verdict(offset, log_prob, settings, steps, dense_check=True, stored_check=slice(5, 6))
    assert isinstance(verdict, int) and verdict >= settings.check_interval


def test_the_run_at_most_doubles_on_an_early_autocorrelation_estimate():
    """A walker that has not moved in the second half of a short run makes tau_int undefined
    (the chain's length): the next chunk is then the run's length, not 50 tau_int more."""
    from bayespig.inference.sampler import _run_verdict

    settings = InferenceSettings(target_ess=400, draws_per_chain=128)
    steps = 400
    chain = np.random.default_rng(2).standard_normal((steps, settings.n_ensembles * settings.n_walkers, 3))
    chain[steps // 2:, 0, 1] = chain[steps // 2, 0, 1]  # stuck
    log_prob = -0.5 * (chain ** 2).sum(axis=2)
    assert _run_verdict(chain, log_prob, settings, steps, dense_check=True) == steps


class _GaussianBlocks:
    """A known joint target with the interface BlockwiseMove uses: phi ~ N(0, 1) and per block
    (wavelength) r ~ N(b phi, Sigma) given phi, so the blocks are coupled through phi."""

    n_wavelengths = 3
    blocks = np.array([[0, 3], [1, 4], [2, 5]])
    shared_slice = slice(6, 7)
    scale_direction = prior_proposal_columns = None  # no exact symmetry, no draws from the prior
    coupling = np.array([[0.8, -0.5], [0.0, 1.2], [-0.6, 0.3]])  # b per block
    block_cov = np.array([[[1.0, 0.6], [0.6, 0.5]], [[0.3, -0.1], [-0.1, 0.2]], [[2.0, 0.0], [0.0, 1.0]]])

    def __init__(self):
        self.calls = 0

    def wavelength_terms(self, u):
        self.calls += u.shape[0]
        phi = u[:, 6:7]
        d = u[:, self.blocks] - phi[:, :, None] * self.coupling[None]  # (W, 3, 2)
        return -0.5 * np.einsum("wbi,bij,wbj->wb", d, np.linalg.inv(self.block_cov), d)

    def log_prior_shared(self, u):
        return -0.5 * u[:, 6] ** 2

    def __call__(self, u):
        return self.log_prior_shared(u) + self.wavelength_terms(u).sum(axis=1)

    def covariance(self):
        cov = np.zeros((7, 7))
        b = np.zeros(6)
        b[self.blocks] = self.coupling
        cov[:6, :6] = np.outer(b, b)
        for k, block in enumerate(self.blocks):
            cov[np.ix_(block, block)] += self.block_cov[k]
        cov[:6, 6] = cov[6, :6] = b
        cov[6, 6] = 1.0
        return cov

def _run_and_check_gaussian(target, move, seed):
    """Run ``move`` mixed with whole-vector DE (as sample_joint runs it) on a _GaussianBlocks
    target for 4000 steps and check the target's mean and covariance within MC_Z Monte Carlo
    errors, the log-probabilities emcee kept and the move's cache of wavelength terms."""
    from bayespig.inference import IndependentEnsemblesMove
    from bayespig.inference.shared import JOINT_DE_WEIGHT

    cov = target.covariance()
    n_ensembles, width = move.n_ensembles, 16
    sampler = emcee.EnsembleSampler(n_ensembles * width, 7, target, vectorize=True,
                                    moves=[(move, 1.0 - JOINT_DE_WEIGHT),
                                           (IndependentEnsemblesMove("de", n_ensembles), JOINT_DE_WEIGHT)])
    sampler.random_state = np.random.RandomState(seed).get_state()
    start = np.random.default_rng(seed).multivariate_normal(np.zeros(7), cov, n_ensembles * width)
    sampler.run_mcmc(start, 4000, progress=False, skip_initial_state_check=True)
    chain = sampler.get_chain(discard=400)
    tau = emcee.autocorr.integrated_time(chain, tol=0, quiet=True).max()
    flat = chain.reshape(-1, 7)
    n_eff = flat.shape[0] / tau
    assert np.all(np.abs(flat.mean(axis=0)) < MC_Z * np.sqrt(np.diag(cov) / n_eff))
    se_cov = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov ** 2) / n_eff)
    assert np.all(np.abs(np.cov(flat.T) - cov) < MC_Z * se_cov)
    assert 0.3 < sampler.acceptance_fraction.mean() < 0.99
    # the log-probabilities emcee kept are the target's, and the cache holds the true terms
    np.testing.assert_allclose(sampler.get_log_prob()[-1], target(sampler.get_chain()[-1]), rtol=1e-12)
    fresh = move._coords == sampler.get_chain()[-1]
    valid = fresh.all(axis=1)
    assert valid.any()
    np.testing.assert_allclose(move._terms[valid], target.wavelength_terms(sampler.get_chain()[-1][valid]),
                               rtol=1e-12)


@pytest.mark.parametrize("gaussian_weight", [None, 0.0, 1.0], ids=["default", "de-blocks", "gaussian-blocks"])
def test_the_block_move_samples_a_known_coupled_gaussian(gaussian_weight):
    """BlockwiseMove mixed with whole-vector DE (as sample_joint runs it), 2 ensembles, with its
    default mixture of block proposals and with each alone (the Gaussian independence proposal
    is 1.5x wider than the blocks' spread, so without its Hastings factor the sampled
    covariance would be too wide): the target's mean and covariance within MC_Z Monte Carlo
    errors, a sane acceptance, and the cached wavelength terms equal to a fresh evaluation at
    every walker's final position."""
    from bayespig.inference.shared import BlockwiseMove

    target = _GaussianBlocks()
    _run_and_check_gaussian(target, BlockwiseMove(target, 2, gaussian_weight=gaussian_weight), seed=5)


class _GaussianBlocksWithSymmetry(_GaussianBlocks):
    """_GaussianBlocks with the two extra moves of a pigment library's base stage: an exact
    symmetry (``r + t b, phi + t``: every ``r - b phi``, so every wavelength term, unchanged;
    only phi's prior varies along it) and phi opted into draws from its N(0, 1) prior with
    the blocks shifted by an arbitrary fixed ``sensitivity`` (any fixed shift keeps the
    proposal's Jacobian one)."""

    n_shared = 1
    scale_step_sd = 0.7
    prior_proposal_columns = (np.array([0]), np.array([0.0]), np.array([1.0]))

    def __init__(self):
        super().__init__()
        self.scale_direction = np.zeros(7)
        self.scale_direction[self.blocks] = self.coupling
        self.scale_direction[6] = 1.0
        self.sensitivity = np.linspace(-0.4, 0.9, 6)[:, None]

    def in_support(self, u):
        return np.ones(np.atleast_2d(u).shape[0], dtype=bool)


def test_the_scale_symmetry_and_prior_draws_keep_a_known_coupled_gaussian():
    """BlockwiseMove's steps 3 (random walk along an exact symmetry, accepted on the priors)
    and 4 (phi drawn from its prior, the blocks shifted, accepted on the likelihood ratio) with
    its steps 1-2 and whole-vector DE: the target's mean and covariance within MC_Z Monte
    Carlo errors, both steps accepted at a proper rate, and the cached wavelength terms equal
    to a fresh evaluation (each step's own acceptance rule: the invariance test below)."""
    from bayespig.inference.shared import BlockwiseMove

    target = _GaussianBlocksWithSymmetry()
    # the symmetry is exact: moving along it changes no wavelength term
    u = np.random.default_rng(3).normal(size=(4, 7))
    np.testing.assert_allclose(target.wavelength_terms(u + 0.8 * target.scale_direction),
                               target.wavelength_terms(u), rtol=1e-12, atol=1e-12)
    move = BlockwiseMove(target, 2)
    _run_and_check_gaussian(target, move, seed=7)
    assert 0.05 < move.scale_accepted / move.scale_proposed < 0.95
    assert 0.05 < move.prior_accepted / move.prior_proposed < 0.95


@pytest.mark.parametrize("step", ["scale symmetry", "prior draws"])
def test_the_scale_symmetry_and_prior_draw_steps_each_leave_the_target_invariant(step):
    """Each of BlockwiseMove's steps 3 and 4 alone is a Metropolis-Hastings kernel of the
    target: applied 10 times to N independent exact draws, the walkers stay independent
    draws of it (mean and covariance within MC_Z errors of N independent draws), though
    the steps moved most of them. Sharper than a whole run, where the other moves dilute a
    wrong acceptance rule of these two."""
    from bayespig.inference.shared import BlockwiseMove

    target = _GaussianBlocksWithSymmetry()
    cov = target.covariance()
    n = 20000
    u = np.random.default_rng(11).multivariate_normal(np.zeros(7), cov, n)
    start = u.copy()
    move = BlockwiseMove(target, 1)
    random = np.random.RandomState(11)
    for _ in range(10):
        terms = target.wavelength_terms(u)
        if step == "scale symmetry":
            u, log_prob, _ = move._scale_moves(u, target(u), terms, random)
            np.testing.assert_allclose(log_prob, target(u), rtol=1e-12)
        else:
            u, new_terms, _ = move._prior_proposals(u, terms, random)
            np.testing.assert_allclose(new_terms, target.wavelength_terms(u), rtol=1e-12)
    assert np.mean(np.any(u != start, axis=1)) > 0.5
    assert np.all(np.abs(u.mean(axis=0)) < MC_Z * np.sqrt(np.diag(cov) / n))
    se_cov = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov ** 2) / n)
    assert np.all(np.abs(np.cov(u.T) - cov) < MC_Z * se_cov)
