"""Constants shared by the inference tests."""

from bayespig.data import simulate
from bayespig.inference import InferenceSettings

#: Monte-Carlo z-score allowed between a sample mean and its expectation (|z| > 4.5 has
#: probability ~7e-6 per comparison for a correct sampler).
MC_Z = 4.5

#: Small but honest runs for the default test run.
FAST = InferenceSettings(n_walkers=16, n_ensembles=4, draws_per_chain=512, target_ess=400)


def method4_data():
    """The simulated method-4 set of the ``method4_set`` fixture (also built in subprocesses)."""
    return simulate(a=[0.05, 0.1, 0.2], tau=[0.5, 1.0, 2.0], design="method4",
                    wavelengths=[450.0, 550.0, 650.0], eps=0.05, seed=11)
