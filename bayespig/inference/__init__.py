"""Bayesian inference per wavelength: emcee posteriors over ``a``, ``tau`` (and ``g``, ``eps``).

For every wavelength the posterior of :class:`bayespig.likelihood.LogPosterior` (the exact
likelihood of the paper's noise model, eq. 7, with the priors of
:class:`bayespig.likelihood.Priors`) is sampled with emcee 3.1.6, and the result of all
wavelengths is one :class:`arviz.InferenceData`.

Modules
-------
``settings``
    :class:`InferenceSettings`, the move mixtures by name, the diagnostics thresholds.
``moves``
    :class:`IndependentEnsemblesMove` (several independent ensembles in one sampler).
``sampler``
    The sampler loop: start ball, pre-burn, stragglers, run-length rule, stacks of wavelengths.
``executors``
    Tasks (stacks of wavelengths) and how they run: serially, a local process pool, or a
    ``concurrent.futures``-style executor.
``outputs``
    Per-wavelength records, value coordinates, provenance.
``shared``
    Parameters shared over wavelengths: one joint posterior in residual coordinates, block-wise
    moves and a pilot start for any list of specs (:class:`~bayespig.inference.shared.SharedParameter`).
``card_factors``
    The first spec: one factor per card on the substrate albedo (``infer(substrate_sd=...)``).
``api``
    :func:`infer` and :func:`infer_problem`.
``summary``, ``storage``
    :func:`summarize`, :func:`diagnose`; :func:`save_inference`, :func:`load_inference`.

Sampling
--------
* **Coordinates**: ``[a, log tau_1..G, (g), (log eps), (log noise_floor)]``; every prior is flat
  on a box there.
* **Independent ensembles**: ``n_ensembles`` ensembles of ``n_walkers`` walkers each run in one
  :class:`emcee.EnsembleSampler` (``vectorize=True``) whose moves only combine walkers of the
  same ensemble (:class:`IndependentEnsemblesMove`): the ensembles are independent Markov
  chains (R-hat between them is meaningful) while every log-probability call still evaluates
  the walkers of all ensembles at once (the call overhead dominates the cost).
* **Stacks of wavelengths**: ``wavelengths_per_run`` (16) wavelengths share one sampler, each
  with its own ensembles, start, run length and diagnostics: the look-up tables do not depend
  on the wavelength, so one vectorised call of the stacked log-posterior per half-step
  evaluates the proposals of all of them, and the per-step costs (table interpolation set-up,
  emcee's bookkeeping) are paid once per stack instead of once per wavelength. A wavelength
  whose run is complete is frozen and its draws are taken at that step.
* **Start**: the point fit of :func:`bayespig.fit.fit_problem`, moved inside the prior's box,
  plus Gaussian jitter shaped by the local curvature of the log-posterior (eigenvalues clipped,
  so that ravines give elongated but bounded balls); draws outside the support or with
  ``log p = -inf`` are redrawn, so no walker starts outside the support.
* **Pre-burn**: ``pre_burn_steps`` steps, after which walkers stranded far below their
  ensemble's log-posterior (:data:`STRAGGLER_LOG_P`) are moved onto jittered good walkers of
  the same ensemble; these steps are discarded.
* **Run length**: in chunks, until the chain after burn-in is at least
  ``min_autocorr_multiple`` (50) integrated autocorrelation times ``tau_int`` long (emcee's
  estimator, averaged over the walkers of each ensemble, largest over ensembles and
  parameters), the effective sample size ``n_ensembles * n_walkers * n_kept / tau_int`` of
  every parameter reaches ``target_ess``, *and* the stored draws pass the diagnostics
  (rank-normalised bulk and tail ESS >= ``target_ess``, R-hat <= 1.01; the walkers of an
  ensemble are correlated, which the per-walker ``tau_int`` does not see); capped at
  ``max_steps`` with a :class:`ConvergenceWarning`. Burn-in: the first
  ``burn_in_multiple * tau_int`` steps.
* **Moves**: ``"auto"`` is 80 % Gaussian independence proposals fitted to the complementary
  half-ensemble and 20 % differential evolution (see :class:`IndependentEnsemblesMove`): on
  method 4's compact posteriors it decorrelates in about 3 steps (DE: 8, stretch: 30), and along
  the curved ravines of method 3 it mixes faster than DE and several times faster than the
  stretch move (``benchmarks/inference.py`` measures every mixture); the DE share keeps local
  moves where a Gaussian fits the posterior poorly. ``"stretch"``, ``"de"``, ``"de-snooker"``,
  ``"stretch-de"``, ``"gaussian"`` and ``"gaussian-de"`` are available.
* **Reproducible**: the seed is split with :class:`numpy.random.SeedSequence` into one child
  per wavelength (jitter, stragglers, posterior-predictive noise; the first wavelength's child
  of a stack seeds emcee's random state), so the samples depend on the seed and the settings
  only, not on the executor or the order in which tasks finish.
* **Parallel**: each stack is one task run through a ``concurrent.futures``-style
  ``executor`` (``submit``; a ``dask.distributed`` client's ``get_executor()`` works);
  the default is a local pool of 2 processes, or serial for a single stack.

InferenceData schema
--------------------
Dimensions: ``chain`` (one per independent ensemble), ``draw`` (``draws_per_chain`` rounded up
to a multiple of ``n_walkers``: evenly thinned post-burn-in steps of the ensemble's walkers,
**flattened walker-major**, ``draw = walker * n_steps_kept + step``, so each walker's thinned
trajectory is a contiguous run and arviz's autocorrelation-based ESS and split R-hat see
ordinary Markov chains), ``wavelength`` [nm], ``group`` (film groups), ``value`` (integer index
of the measured values at one wavelength, films concatenated in problem order), ``parameter``.

``posterior``
    ``a`` (chain, draw, wavelength); ``tau`` (chain, draw, wavelength): ``tau`` of the first
    film group (the thin film; for method 1 the film on glass, from its transmittance), absent
    only when every film is opaque; ``tau_group`` (chain, draw, wavelength, group) when there
    is more than one group; ``g`` when ``g="free"``; ``eps`` when inferred; ``noise_floor``
    (chain, draw, wavelength) when inferred (``infer(noise_floor="infer")``); ``r_s_factor``
    (chain, draw, card) with ``substrate_sd`` (one run over all wavelengths: the draws of
    different wavelengths are then joint draws, not independent runs).
``posterior_predictive``
    ``y`` (chain, draw, wavelength, value): the noise-free model prediction of every measured
    value; ``y_rep`` with the noise of eq. (7) added when ``settings.predictive_noise``
    (single precision, as the log-likelihood).
``observed_data``
    ``y`` (wavelength, value).
``log_likelihood``
    ``y`` (chain, draw, wavelength, value): pointwise log-likelihood of eq. (7) (with the
    noise floor when there is one), single precision.
``constant_data``
    ``r_s`` (wavelength, value): substrate albedo seen from the binder per value (0 for
    transmittance and opaque films); ``eps`` (wavelength, value): known relative error (NaN
    where inferred); ``noise_floor`` (wavelength, value): the additive floor (0 without one, NaN
    where inferred); ``point_a``, ``point_tau`` (wavelength): the point fit (``point_tau`` of
    the first group).
``sample_stats``
    ``lp`` (chain, draw, wavelength): log posterior (= log-likelihood plus a constant);
    ``acceptance_rate`` (chain, wavelength); ``autocorr_time`` (wavelength, parameter) in
    steps; ``n_steps``, ``n_burn_in`` (wavelength); ``thinning`` (wavelength): steps between
    stored draws; ``max_steps_reached`` (wavelength, 0/1); ``adaptation_rounds`` (wavelength):
    the joint sampler's adaptation runs before its run proper (0 for a per-wavelength run);
    ``shared_acceptance`` (wavelength): the share of the joint sampler's proposals of the
    parameters shared over wavelengths that were accepted (NaN for a per-wavelength run; a few
    per cent means the shared parameters crawl, :mod:`bayespig.inference.shared`).

Non-dimension coordinates along ``value``: ``sample`` (film name), ``channel`` (channel label,
e.g. ``45as15``, ``sci``; ``specular_transmittance`` for a film on glass), ``kind``
(``reflectance``/``transmittance``), ``film_group`` (``""`` for opaque films).

Attributes (on the InferenceData and on every group): ``bayespig_version``,
``numpy_version``, ``scipy_version``, ``emcee_version``, ``arviz_version``, ``seed``,
``method``, ``g``, ``eps_mode`` (``known``/``inferred``), ``settings`` (JSON), ``priors``
(JSON of :meth:`Priors.describe`), ``table_keys`` (JSON list), ``table_checksums`` (JSON: key
-> SHA-256 of the table's arrays; the same checksum is the same numbers, bit for bit),
``instruments`` (JSON: name ->
channel labels), ``n`` (binder index), ``parameter_names`` (JSON), ``created`` (UTC ISO time),
``sampling_wall_time_s``, ``substrate_factors`` (JSON; null without card factors),
``noise_floor_mode`` (``none``/``known``/``inferred``), ``noise_floor`` (the known floor; 0 for
none, NaN when inferred) and ``noise_floor_units`` (those of the values: ``1/sr`` for BRDFs).

Variable attributes: every posterior variable has ``long_name`` and ``units`` (``"1"``, all
are dimensionless except ``noise_floor``, in the values' units;
:data:`~bayespig.inference.outputs.VARIABLE_ATTRS`), the ``wavelength`` coordinate of every
group ``units="nm"``.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), eq. (7) (noise model), section 3 (methods).
Foreman-Mackey et al. (2013), emcee; Nelson et al. (2014) and ter Braak & Vrugt (2008),
differential-evolution moves; Vehtari et al. (2021), rank-normalised R-hat and ESS.
"""

# the public names, and helpers that the studies and benchmarks import from here
from .api import _point_starts, _resolve_eps, infer, infer_problem  # noqa: F401
from .moves import IndependentEnsemblesMove, _moves  # noqa: F401
from .outputs import PRIOR_BOUNDS_ATTR, _prior_bounds, _versions, _wavelength_outputs  # noqa: F401
from .sampler import _autocorr_times, _initial_walkers, _sample_stack, _sample_wavelength  # noqa: F401
from .settings import ESS_MIN, MOVES, RHAT_MAX, ConvergenceWarning, InferenceSettings  # noqa: F401
from .storage import load_inference, save_inference
from .summary import diagnose, summarize

__all__ = [
    "MOVES",
    "ConvergenceWarning",
    "IndependentEnsemblesMove",
    "InferenceSettings",
    "diagnose",
    "infer",
    "infer_problem",
    "load_inference",
    "save_inference",
    "summarize",
]
