"""Benchmark: the joint sampler's adaptation rounds on a Cornell paint with flakes (issues 16, 17).

Run from the repository root (prints only; ~4 min on 2 cores; data in ``../shared/data/cornell``
or ``$BAYESPIG_CORNELL``)::

    python benchmarks/joint_adaptation.py

The Krylon blue enamel (opaque, > 2 deg from the mirror, bands 450, 550, 650 nm) with the
roughness, the binder index, the flakes and a per-band noise floor inferred: the joint run of
:func:`bayespig.inference.shared.sample_blocks` once with a single adaptation run (the sampler
before session 11, ``MAX_ADAPTATION_ROUNDS = 1``) and once with the repeated adaptation (the
default). Printed per variant: wall time, steps of the run proper, whether it was capped, the
share of the shared block's proposals accepted, and the ESS (arviz, bulk) of the shared
parameters and of ``a`` per band. Then the Revigo card-factor runs of films 07A, 02B and 14B
(``infer(..., method="method4", eps=0.01, substrate_sd=0.1)``, SCI; ~30 s; data in
``../shared/data/revigo``), whose first adaptation settles: steps, time, and the smallest ESS
and largest R-hat of the card factors.
"""

import os
import sys
import time
import warnings
from pathlib import Path

import arviz as az
import numpy as np

import bayespig
from bayespig.inference import InferenceSettings
from bayespig.inference import shared

REVIGO = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "revigo"
DATA = Path(os.environ.get("BAYESPIG_CORNELL", Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "cornell"))


def run(rounds, max_steps=4000):
    """One joint run with ``rounds`` adaptation rounds at most; returns the printed line's parts."""
    accepted = []
    propose = shared.BlockwiseMove.propose

    def counting(self, model, state):
        before = state.coords[:, self.log_post.shared_slice].copy()
        out = propose(self, model, state)
        accepted.append(np.mean((state.coords[:, self.log_post.shared_slice] != before).any(axis=1)))
        return out

    saved = shared.MAX_ADAPTATION_ROUNDS
    shared.MAX_ADAPTATION_ROUNDS, shared.BlockwiseMove.propose = rounds, counting
    try:
        ms = bayespig.read_measurements(DATA / "krylon_blue.astm", opaque=True)
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            idata = bayespig.infer(ms, seed=0, roughness="free", binder_index="free", flakes=True,
                                   noise_floor="infer", exclude_mirror_deg=2, wavelengths=[450, 550, 650],
                                   progress=False, settings=InferenceSettings(max_steps=max_steps, target_ess=400))
        elapsed = time.perf_counter() - start
    finally:
        shared.MAX_ADAPTATION_ROUNDS, shared.BlockwiseMove.propose = saved, propose
    post = idata.posterior
    ess = {}
    for name in ("roughness", "binder_index", "flake_roughness", "a"):
        x = post[name].values.reshape(post.sizes["chain"], post.sizes["draw"], -1)
        ess[name] = [float(az.ess(x[:, :, j])) for j in range(x.shape[2])]
    capped = any("max_steps" in str(w.message) for w in caught)
    steps = int(np.max(idata.sample_stats["n_steps"].values))
    return elapsed, steps, capped, float(np.mean(accepted)), ess


def main():
    if not (DATA / "krylon_blue.astm").exists():
        sys.exit(f"benchmark needs {DATA / 'krylon_blue.astm'} (set BAYESPIG_CORNELL)")
    print("Krylon blue, 450/550/650 nm, roughness + binder index + flakes + noise floor, max 4000 steps")
    for label, rounds in (("one adaptation run", 1), (f"up to {saved_default} rounds (default)", saved_default)):
        elapsed, steps, capped, acc, ess = run(rounds)
        print(f"{label}: {elapsed:.0f} s, {steps} steps{' (capped)' if capped else ''}, shared moves accepted "
              f"{100 * acc:.1f} %; ESS roughness {ess['roughness'][0]:.0f}, binder index {ess['binder_index'][0]:.0f}, "
              f"flake roughness {ess['flake_roughness'][0]:.0f}, a " + " / ".join(f"{v:.0f}" for v in ess["a"]))

    revigo = REVIGO / "revigo-aggregated-palette-spectral-data.txt"
    if not revigo.exists():
        sys.exit(f"the Revigo part needs {revigo}")
    from bayespig.data.spectral_table import read_revigo

    films = read_revigo(revigo, specular="included")
    for film in ("07A", "02B", "14B"):
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            idata = bayespig.infer(films[film], method="method4", eps=0.01, seed=0, progress=False,
                                   settings=InferenceSettings(target_ess=400, draws_per_chain=128),
                                   substrate_sd=0.1)
        elapsed = time.perf_counter() - start
        f = idata.posterior["r_s_factor"].values
        f = f.reshape(f.shape[0], f.shape[1], -1)
        ess = min(float(az.ess(f[:, :, j])) for j in range(f.shape[2]))
        rhat = max(float(az.rhat(f[:, :, j])) for j in range(f.shape[2]))
        capped = any("max_steps" in str(w.message) for w in caught)
        steps = int(np.max(idata.sample_stats["n_steps"].values))
        print(f"Revigo {film}, card factors: {steps} steps{' (capped)' if capped else ''}, {elapsed:.1f} s, "
              f"smallest factor ESS {ess:.0f}, largest R-hat {rhat:.3f}")


saved_default = shared.MAX_ADAPTATION_ROUNDS

if __name__ == "__main__":
    main()
