"""The sampler loop: start ball, pre-burn, stragglers, run-length rule, stacks of wavelengths."""

from __future__ import annotations

import math

import numpy as np

from .moves import _moves
from .settings import RHAT_MAX


def _inside(theta, lower, upper, margin=1e-6):
    span = upper - lower
    return np.clip(theta, lower + margin * span, upper - margin * span)


def _start_covariance(log_post, theta0):
    """Covariance of the start ball: inverse of the negative Hessian of log p at ``theta0``.

    Finite differences (one vectorised call); eigenvalues of the covariance are clipped to
    ``[(1e-6 span)^2, (span / 4)^2]`` so that flat directions (ravines, plateaus) give a
    bounded ball and a non-concave point a small one.
    """
    n_dim = theta0.size
    span = log_post.upper - log_post.lower
    h = 1e-4 * span
    points = [theta0]
    for i in range(n_dim):
        for j in range(i, n_dim):
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                p = theta0.copy()
                p[i] += si * h[i]
                p[j] += sj * h[j]
                points.append(p)
    points = _inside(np.array(points), log_post.lower, log_post.upper, margin=0.0)
    values = log_post(points)
    hessian = np.zeros((n_dim, n_dim))
    k = 1
    for i in range(n_dim):
        for j in range(i, n_dim):
            pp, pm, mp, mm = values[k:k + 4]
            k += 4
            hessian[i, j] = hessian[j, i] = (pp - pm - mp + mm) / (4.0 * h[i] * h[j])
    scale = np.diag(span)
    if not np.isfinite(hessian).all():
        return scale @ np.eye(n_dim) @ scale * 1e-6
    # in units of the box so that the clipping is meaningful for every coordinate
    precision = -(scale @ hessian @ scale)
    eigval, eigvec = np.linalg.eigh(0.5 * (precision + precision.T))
    variance = 1.0 / np.clip(eigval, 16.0, 1e12)
    return scale @ (eigvec * variance) @ eigvec.T @ scale


def _initial_walkers(log_post, theta0, n_total, jitter, rng):
    """``n_total`` start points inside the support with finite log-posterior."""
    theta0 = _inside(np.asarray(theta0, dtype=float), log_post.lower, log_post.upper, margin=1e-3)
    cov = _start_covariance(log_post, theta0) * jitter ** 2
    chol = np.linalg.cholesky(cov + 1e-18 * np.eye(theta0.size))
    walkers = np.empty((n_total, theta0.size))
    missing = np.arange(n_total)
    for _ in range(100):
        draws = theta0 + rng.standard_normal((missing.size, theta0.size)) @ chol.T
        ok = log_post.in_support(draws)
        if ok.any():
            ok[ok] = np.isfinite(log_post(draws[ok]))
        walkers[missing[ok]] = draws[ok]
        missing = missing[~ok]
        if missing.size == 0:
            return walkers
        chol = chol * 0.5
    raise RuntimeError(f"could not place walkers with finite log-posterior around {theta0}")


def _autocorr_times(chain, n_ensembles):
    """Integrated autocorrelation time per parameter [steps], largest over the ensembles.

    A walker that did not move at all (stuck) makes the estimate undefined; it is then the
    chain length (not converged).
    """
    from emcee.autocorr import integrated_time

    width = chain.shape[1] // n_ensembles
    if (np.ptp(chain, axis=0) == 0).any():
        return np.full(chain.shape[2], float(chain.shape[0]))
    taus = [integrated_time(chain[:, k * width:(k + 1) * width], c=5, tol=0, quiet=True)
            for k in range(n_ensembles)]
    tau = np.max(taus, axis=0)
    return np.where(np.isfinite(tau), tau, float(chain.shape[0]))


#: A walker this far (in log-posterior) below its ensemble's median after the pre-burn is a
#: straggler: for a d-dimensional near-Gaussian posterior the spread of log p is ~ sqrt(d / 2).
STRAGGLER_LOG_P = 25.0


def _replace_stragglers(coords, log_prob, log_post, n_ensembles, rng):
    """Move walkers far below their ensemble's median log p onto (jittered) good walkers.

    ``coords`` (n_walkers, n_dim) and ``log_prob`` (n_walkers,) of one wavelength are
    changed in place.
    """
    width = coords.shape[0] // n_ensembles
    for k in range(n_ensembles):
        block = np.arange(k * width, (k + 1) * width)
        lp = log_prob[block]
        bad = block[lp < np.median(lp) - STRAGGLER_LOG_P]
        good = block[lp >= np.median(lp)]
        if bad.size == 0:
            continue
        spread = coords[good].std(axis=0) + 1e-12
        for walker in bad:
            for _ in range(20):
                candidate = coords[rng.choice(good)] + 1e-2 * spread * rng.standard_normal(coords.shape[1])
                value = log_post(candidate[None])[0] if log_post.in_support(candidate[None])[0] else -np.inf
                if np.isfinite(value):
                    coords[walker], log_prob[walker] = candidate, value
                    break


def _stored_draws_pass(theta, target_ess):
    """Rank-normalised bulk and tail ESS >= target and R-hat <= RHAT_MAX for every parameter."""
    import arviz as az

    for k in range(theta.shape[-1]):
        x = theta[..., k]
        if az.rhat(x) > RHAT_MAX:
            return False
        if min(az.ess(x, method="bulk"), az.ess(x, method="tail")) < target_ess:
            return False
    return True


def _run_verdict(chain, log_prob, settings, steps, dense_check=False, stored_check=None):
    """Whether the run of one wavelength is complete after ``steps`` steps.

    Parameters
    ----------
    chain, log_prob : numpy.ndarray
        Post-pre-burn chain (steps, walkers, n_dim) and log-posterior (steps, walkers) of the
        wavelength's ensembles.
    dense_check : bool
        Check R-hat and ESS on the post-burn-in chain thinned by half the largest
        autocorrelation time instead of on the stored draws. For many parameters at once (a
        joint run): on ``draws_per_chain`` = 128 independent draws per chain, R-hat <= 1.01 and
        ESS >= 400 fail by chance for ~10 % of the parameters each, so a check of ~90 of them
        on the stored draws alone fails at every check and the run goes to ``max_steps``.
    stored_check : slice or numpy.ndarray, optional
        Coordinates whose stored draws must pass too when ``dense_check`` (the few shared
        parameters of a joint run, which a user reads off the stored draws: card factors,
        roughness, thicknesses). Their chance failure rate on the stored draws is small for a
        few coordinates, so the run ends soon after they pass.

    Returns
    -------
    dict or int
        The run's results (draws, statistics) when complete (or capped at ``max_steps``), else
        the number of further steps before the next check.
    """
    n_chains, width, kept = settings.n_ensembles, settings.n_walkers, settings.steps_kept
    n_member = n_chains * width

    def per_chain(x):  # (kept, n_member, ...) -> (chains, walkers * kept, ...), walker-major
        x = x.reshape((kept, n_chains, width) + x.shape[2:])
        x = np.moveaxis(x, 0, 2)  # (chains, walkers, kept, ...)
        return x.reshape((n_chains, width * kept) + x.shape[3:])

    # tau_int from the second half (free of the start transient), then burn-in from it
    tau = _autocorr_times(chain[steps // 2:], n_chains)
    tau_max = float(tau.max())
    burn = max(0, min(math.ceil(settings.burn_in_multiple * tau_max), steps - kept))
    ess = n_member * (steps - burn) / tau
    needed = max(settings.min_autocorr_multiple * tau_max, settings.target_ess * tau_max / n_member, kept) + burn
    thin = max(1, (steps - burn) // kept)
    rows = steps - 1 - thin * np.arange(kept)[::-1]
    theta = per_chain(chain[rows])
    complete = False
    if steps >= needed and (ess >= settings.target_ess).all():
        # emcee's criterion met; the stored draws must pass the diagnostics too (walkers of
        # an ensemble are correlated, which the per-walker tau_int does not see)
        if dense_check:
            spacing = max(1, int(tau_max // 2))
            dense_rows = steps - 1 - spacing * np.arange((steps - burn) // spacing)[::-1]
            checked = np.moveaxis(chain[dense_rows].reshape((dense_rows.size, n_chains, width) + chain.shape[2:]),
                                  0, 2).reshape((n_chains, width * dense_rows.size) + chain.shape[2:])
        else:
            checked = theta
        complete = _stored_draws_pass(checked, settings.target_ess)
        if complete and dense_check and stored_check is not None:
            complete = _stored_draws_pass(theta[..., stored_check], settings.target_ess)
        chunk = max(settings.check_interval, steps // 2)
    else:
        # extrapolated from tau_int, but at most doubling the run: tau_int of a short chain is
        # unreliable (a walker that has not moved in some coordinate sets it to the chain's
        # length), and one bad estimate must not send the run to many times its need
        chunk = max(settings.check_interval, min(int(1.1 * needed) - steps, steps))
    capped = not complete and steps >= settings.max_steps
    if not (complete or capped):
        return chunk
    return {"theta": theta, "lp": per_chain(log_prob[rows]), "autocorr_time": tau, "n_steps": steps,
            "n_burn_in": burn, "thin": thin, "max_steps_reached": capped}


def _sample_stack(stacked, singles, starts, settings, seed_sequences, moves=None, start_walkers=None,
                  dense_check=False, stored_check=None):
    """emcee run of a stack of wavelengths in one sampler; one run record per wavelength.

    Every wavelength has ``n_ensembles`` ensembles of ``n_walkers`` walkers of its own
    (contiguous blocks; moves never mix blocks), so its chains are those of a run of its own,
    but the proposals of all wavelengths are evaluated in one call of the stacked
    log-posterior per half-step: the table interpolation and emcee's bookkeeping are paid
    once per step for the whole stack. A wavelength whose run is complete is frozen (its
    blocks no longer move or cost anything) and its draws are taken at that step, so its run
    length is its own.

    Parameters
    ----------
    stacked : LogPosterior
        Log-posterior of the stack (``index`` = the wavelengths).
    singles : list of LogPosterior
        The same per wavelength (start, stragglers).
    starts : numpy.ndarray
        Point-fit start per wavelength, (n_stack, n_dim).
    settings : InferenceSettings
    seed_sequences : list of numpy.random.SeedSequence
        One per wavelength (its start jitter, stragglers, predictive noise); the first one's
        also seeds emcee's random state of the stack.
    moves : list, optional
        ``(move, weight)`` pairs replacing the settings' mixture (a stack of one member; e.g.
        :class:`bayespig.inference.shared.BlockwiseMove`, which needs fewer walkers
        than ``2 n_dim``).
    start_walkers : numpy.ndarray, optional
        Every walker's start (n_stack * n_ensembles * n_walkers, n_dim) instead of a ball
        around ``starts``.
    dense_check : bool
        The diagnostics on the thinned chain rather than the stored draws (:func:`_run_verdict`).
    stored_check : slice or numpy.ndarray, optional
        With ``dense_check``, coordinates whose stored draws must pass as well (:func:`_run_verdict`).

    Returns
    -------
    list of dict
    """
    import emcee

    n_stack, n_dim = len(singles), stacked.n_dim
    if settings.n_walkers < 2 * n_dim * (moves is None) or settings.n_walkers % 2 or settings.n_walkers < 6:
        raise ValueError(f"InferenceSettings.n_walkers must be even, >= 6 and >= 2 * n_dim = "
                         f"{2 * n_dim} for parameters {stacked.parameter_names}")
    n_chains = settings.n_ensembles
    per_member = n_chains * settings.n_walkers
    children = [seq.spawn(4) for seq in seed_sequences]  # jitter, emcee, predictive, stragglers
    if start_walkers is None:
        start = np.concatenate([
            _initial_walkers(single, theta0, per_member, settings.jitter, np.random.default_rng(child[0]))
            for single, theta0, child in zip(singles, starts, children)])
    else:
        start = np.array(start_walkers, dtype=float)
    member_of_walker = np.repeat(np.arange(n_stack), per_member)

    def log_prob_of_all(coords):  # emcee's interface: every walker of the stack
        return stacked(coords, member=member_of_walker)

    custom = moves is not None  # may have fewer walkers than dimensions (emcee's start check does not apply)
    moves = _moves(settings, n_dim, n_stack, stacked) if moves is None else moves
    sampler = emcee.EnsembleSampler(n_stack * per_member, n_dim, log_prob_of_all, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(np.random.MT19937(children[0][1])).get_state()

    # pre-burn: let the ensembles spread out, then move stragglers (walkers stranded far below
    # their ensemble's log-posterior, which ensemble moves cannot bring back), and start afresh
    state = sampler.run_mcmc(start, settings.pre_burn_steps, progress=False, skip_initial_state_check=custom)
    for k, (single, child) in enumerate(zip(singles, children)):
        block = slice(k * per_member, (k + 1) * per_member)
        _replace_stragglers(state.coords[block], state.log_prob[block], single, n_chains,
                            np.random.default_rng(child[3]))
    sampler.reset()
    runs = [None] * n_stack
    steps, chunk = 0, max(settings.min_steps, settings.check_interval)
    while any(run is None for run in runs):
        live = np.array([run is None for run in runs])
        for move, _ in moves:
            move.frozen = np.repeat(~live, n_chains)
        chunk = int(min(chunk, settings.max_steps - steps))
        state = sampler.run_mcmc(state, chunk, progress=False, skip_initial_state_check=True)
        steps += chunk
        chain, log_prob = sampler.get_chain(), sampler.get_log_prob()
        accepted = sampler.backend.accepted
        chunks = []
        for k in np.flatnonzero(live):
            block = slice(k * per_member, (k + 1) * per_member)
            verdict = _run_verdict(chain[:, block], log_prob[:, block], settings, steps, dense_check,
                                   stored_check)
            if isinstance(verdict, dict):
                verdict["acceptance_rate"] = (accepted[block] / steps).reshape(n_chains, -1).mean(axis=1)
                verdict["predictive_seed"] = children[k][2]
                runs[k] = verdict
            else:
                chunks.append(verdict)
        chunk = min(chunks, default=0)
    return runs


def _sample_wavelength(log_post, theta0, settings, seed_sequence):
    """emcee run at one wavelength (a stack of one); returns its run record."""
    return _sample_stack(log_post, [log_post], np.asarray(theta0, dtype=float)[None], settings,
                         [seed_sequence])[0]
