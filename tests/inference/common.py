"""Constants shared by the inference tests."""

from bayespig.inference import InferenceSettings

#: Monte-Carlo z-score allowed between a sample mean and its expectation (|z| > 4.5 has
#: probability ~7e-6 per comparison for a correct sampler).
MC_Z = 4.5

#: Small but honest runs for the default test run.
FAST = InferenceSettings(n_walkers=16, n_ensembles=4, draws_per_chain=512, target_ess=400)
