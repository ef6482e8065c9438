"""Outputs of the runs: per-wavelength records, value coordinates and provenance."""

from __future__ import annotations

import numpy as np

#: Storage type of the per-draw predictions and pointwise log-likelihoods.
STORED_DRAW_DTYPE = np.float32


def _wavelength_outputs(log_post, run, settings):
    """Posterior quantities, predictions and pointwise log-likelihood from one run."""
    theta = run.pop("theta")
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    a, tau, g, eps = log_post.unpack(flat)
    model = log_post.evaluate(a, tau, g if log_post.free_g else None)
    pointwise = log_post.log_likelihood(flat, pointwise=True)
    shape = (n_chains, n_draws)
    out = {
        "a": a.reshape(shape),
        "tau": tau.reshape(shape + (tau.shape[1],)),
        "y": model.reshape(shape + (-1,)),
        "log_likelihood": pointwise.reshape(shape + (-1,)),
        **run,
    }
    if log_post.free_g:
        out["g"] = g.reshape(shape)
    if log_post.infer_eps:
        k = 1 + log_post.n_groups + log_post.free_g
        out["eps"] = np.exp(flat[:, k]).reshape(shape)
    if settings.predictive_noise:
        rng = np.random.default_rng(run["predictive_seed"])
        noisy = model * (1.0 + np.broadcast_to(eps, model.shape) * rng.standard_normal(model.shape))
        out["y_rep"] = noisy.reshape(shape + (-1,))
    out.pop("predictive_seed")
    return out


def _value_coordinates(problem):
    """Per measured value: sample, channel, kind, film_group, and r_s (n_wavelengths, n_values)."""
    sample, channel, kind, group, r_s = [], [], [], [], []
    for film in problem.films:
        k = film.observed.shape[1]
        sample += [film.name.split(":")[0]] * k
        kind += [film.kind] * k
        group += [film.group or ""] * k
        if film.kind == "transmittance":
            channel += ["specular_transmittance"] * k
        else:
            channel += list(film.instrument.labels)
        r_s.append(np.repeat(np.asarray(film.r_s, dtype=float)[:, None], k, axis=1))
    return sample, channel, kind, group, np.concatenate(r_s, axis=1)


def _versions():
    import arviz
    import emcee
    import scipy

    from .. import __version__

    return {"bayespig_version": __version__, "numpy_version": np.__version__,
            "scipy_version": scipy.__version__, "emcee_version": emcee.__version__,
            "arviz_version": arviz.__version__}
