"""Sample design (issue 8): Fisher information of eq. (7), ranking, full-posterior checks, report.

References: the Monte-Carlo variance of the score (finite differences of the exact
log-likelihood of eq. 7 on simulated noise; its covariance *is* the Fisher information),
the analytic sd of method 1's tau (eq. 5: ``sd(tau) = 1 / sqrt(1/eps^2 + 2)``, the paper's
"method 1's tau error = eps"), the paper's section 3.2.2 (a thin film on white alone is a
poor design), and full posteriors from :func:`bayespig.infer`.
"""

import json

import numpy as np
import pytest

from bayespig.data.simulate import FilmSpec
from bayespig.inference import InferenceSettings
from bayespig.likelihood import multiplicative_normal_logpdf
from bayespig.physics.forward import specular_transmittance
from bayespig.studies.design import (
    Candidate,
    DesignPrior,
    candidate_designs,
    check_designs,
    fisher_information,
    method_candidate,
    parse_substrate,
    posterior_sd,
    rank_designs,
    write_design_report,
)
from bayespig.table import load_table

#: Fisher-information sd against the posterior sd where the posterior is well identified
#: (issue 6's factor for posterior sd against frequentist RMS).
FISHER_POSTERIOR_FACTOR = 1.5
#: Every branch of the Fisher code: opaque film, film on glass, film on a grey substrate.
MIXED = (FilmSpec("opaque", opaque=True), FilmSpec("glass", on_glass=True, tau_scale=0.5),
         FilmSpec("grey", substrate=0.3, film_group="g"), FilmSpec("white", substrate="white", film_group="g"))


@pytest.fixture(scope="module")
def table():
    return load_table("multi-angle-45", progress=False)


def _log_likelihood(table, films, observed, a, log_tau, eps):
    """Exact log-likelihood of eq. (7) of every replicate (rows of ``observed``), one shared tau."""
    tau = np.exp(log_tau)
    parts = []
    for f in films:
        if f.on_glass:
            parts.append(specular_transmittance(tau * f.tau_scale)[None])
        else:
            t = np.inf if f.opaque else tau * f.tau_scale
            r_s = 0.0 if f.opaque else parse_substrate(f.substrate)
            parts.append(table(a=a, tau=t, r_s=r_s).reshape(-1))
    model = np.concatenate(parts)
    return multiplicative_normal_logpdf(observed, model, eps).sum(axis=1), model


@pytest.mark.parametrize("eps", [0.05, 0.5])
def test_fisher_equals_monte_carlo_score_covariance(table, eps):
    # the score's covariance under the data's law is the Fisher information; eps = 0.5 makes the
    # log-sigma term (2/m^2 against 1/eps^2 = 4) a 50 % effect, which the comparison would see
    a, log_tau = 0.1, np.log(0.8)
    films = MIXED
    _, model = _log_likelihood(table, films, np.zeros((1, 1)), a, log_tau, eps)
    rng = np.random.default_rng(1)
    n_rep = 40000
    observed = model * (1.0 + eps * rng.standard_normal((n_rep, model.size)))
    h = 1e-5  # central differences of a smooth (cubic) interpolant: error ~h^2, far below MC error
    score = np.stack([
        (_log_likelihood(table, films, observed, a + h, log_tau, eps)[0]
         - _log_likelihood(table, films, observed, a - h, log_tau, eps)[0]) / (2 * h),
        (_log_likelihood(table, films, observed, a, log_tau + h, eps)[0]
         - _log_likelihood(table, films, observed, a, log_tau - h, eps)[0]) / (2 * h),
    ])
    mc = np.cov(score)
    # tau_link="proportional": one log tau for all films, as the likelihood above has
    fisher, names = fisher_information(films, a=a, tau=0.8, eps=eps, tau_link="proportional", tables={})
    assert names == ["a", "log_tau[tau]"]
    # MC error of a variance from 40000 draws is ~sqrt(2/40000) = 0.7 %; 4 % is > 5 sigma
    rel_tol = 0.04
    np.testing.assert_allclose(np.diag(fisher), np.diag(mc), rtol=rel_tol)
    corr_mc = mc[0, 1] / np.sqrt(mc[0, 0] * mc[1, 1])
    corr_f = fisher[0, 1] / np.sqrt(fisher[0, 0] * fisher[1, 1])
    assert abs(corr_mc - corr_f) < 0.02  # MC error of a correlation ~ 1/sqrt(n) = 0.005


def test_method1_tau_sd_is_eps():
    # eq. (5): log T = const - tau, so F_tt = (1/eps^2 + 2) tau^2 and sd(tau) = 1/sqrt(1/eps^2 + 2);
    # the paper's Table 2 gives 0.05 = eps for method 1 at every (a0, tau0)
    a0, tau0 = np.array([0.025, 0.1, 0.2]), np.array([0.5, 1.0, 2.0])
    for eps in (0.02, 0.05):
        fisher, names = fisher_information("method1", a=a0, tau=tau0, eps=eps, tables={})
        sd, corr = posterior_sd(fisher, names)
        # the prior box adds 12 / log(1e4)^2 = 0.14 to F_tt >= 625: a 1e-3 relative effect at most
        np.testing.assert_allclose(sd[:, 1] * tau0, 1.0 / np.sqrt(1 / eps**2 + 2), rtol=1e-3)
        np.testing.assert_allclose(corr, 0.0, atol=1e-12)  # opaque film and glass inform disjoint parameters


def test_prior_bounds_unidentified_directions():
    # an opaque film says nothing about tau: its sd is the prior box's, log(1e4)/sqrt(12)
    fisher, names = fisher_information([FilmSpec("opaque", opaque=True)], a=0.1, tau=1.0, tables={})
    assert names == ["a"]
    sd, _ = posterior_sd(fisher, names)
    assert np.isfinite(sd).all()
    # method 3 at tau0 = 0.5 is a ravine: Fisher sd of log tau far above method 4's
    f3, n3 = fisher_information("method3", a=0.1, tau=0.5, tables={})
    f4, n4 = fisher_information("method4", a=0.1, tau=0.5, tables={})
    assert posterior_sd(f3, n3)[0][1] > 10 * posterior_sd(f4, n4)[0][1]
    assert abs(posterior_sd(f3, n3)[1]) > 0.99


def test_thin_film_on_white_only_ranks_below_method4():
    # paper section 3.2.2: a thin film on white alone hardly constrains tau (and with it a)
    prior = DesignPrior(a=(0.02, 0.2), tau_per_um=(0.02, 0.1))
    candidates = [c for c in candidate_designs([10.0], ["black", "white"]) if "opaque" not in c.name]
    result = rank_designs(candidates, prior, n_draws=8, seed=3)
    names = [c.name for c in result.candidates]
    assert names.index("10um on black + white") < names.index("10um on white only")
    assert names[0] != "10um on white only"


def test_thick_film_favours_an_opaque_film_method():
    # tau of the film 4–10: method 4's films are nearly opaque; the transmittance (method 1) and
    # the opaque film (methods 1, 2) carry tau and a (paper section 4.2, Table 2 at tau0 = 2)
    prior = DesignPrior(a=(0.05, 0.3), tau_per_um=(0.2, 0.5))
    candidates = [method_candidate(m, 20.0) for m in ("method1", "method2", "method3", "method4")]
    result = rank_designs(candidates, prior, n_draws=8, seed=0)
    assert result.candidates[0].name.split()[0] in ("method1", "method2")
    assert result.candidates[-1].name.startswith("method3")


def test_ranking_is_the_per_candidate_fisher_and_reproducible():
    prior = DesignPrior(wavelengths=(450.0, 550.0, 650.0))
    candidates = candidate_designs([5.0, 20.0], ["black", "white", "grey:0.4"], ["multi-angle-45", "8d-sci"])
    first = rank_designs(candidates, prior, n_draws=4, seed=7)
    again = rank_designs(candidates[::-1], prior, n_draws=4, seed=7)
    assert [c.name + c.instrument for c in first.candidates] == [c.name + c.instrument for c in again.candidates]
    np.testing.assert_array_equal(first.score, again.score)
    # the shared-film cache gives what a fresh evaluation of one candidate gives
    best = first.candidates[0]
    fisher, names = fisher_information(best, a=first.a, tau=first.tau_per_um, tables={})
    sd, _ = posterior_sd(fisher, names)
    np.testing.assert_allclose(first.rel_sd_a[0], sd[..., 0] / first.a, rtol=1e-12)
    assert {"seed", "eps", "prior", "versions"} <= set(first.settings)


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="substrate"):
        parse_substrate("purple")
    with pytest.raises(ValueError, match="albedo"):
        parse_substrate("grey:1.5")
    with pytest.raises(ValueError, match="a range"):
        DesignPrior(a=(0.3, 0.01))
    with pytest.raises(ValueError, match="per band"):
        DesignPrior(a=[0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="no films"):
        Candidate("empty", ())
    with pytest.raises(ValueError, match="eps"):
        fisher_information("method4", a=0.1, tau=1.0, eps=0.0)
    with pytest.raises(ValueError, match="objective"):
        rank_designs([method_candidate("method4")], objective="colour")
    with pytest.raises(ValueError, match="thicknesses"):
        candidate_designs([0.0])


def test_check_against_full_posterior_and_report(tmp_path):
    # method 4 at tau ~ 0.5 is well identified: Fisher and posterior sd agree within 1.5
    prior = DesignPrior(a=[0.1, 0.1], tau_per_um=[0.05, 0.05], wavelengths=(500.0, 600.0), spread=0.0)
    result = rank_designs([method_candidate("method4", 10.0), method_candidate("method3", 10.0)], prior,
                          n_draws=1, seed=0)
    assert result.candidates[0].name == "method4 10"
    settings = InferenceSettings(target_ess=300, draws_per_chain=256, max_steps=3000)
    checks = check_designs(result, top=1, bands=[0], settings=settings, seed=2)
    assert len(checks) == 1 and checks[0]["candidate"] == "method4 10"
    ratios = np.array([checks[0]["ratio_a"], checks[0]["ratio_tau"]])
    assert ((1 / FISHER_POSTERIOR_FACTOR <= ratios) & (ratios <= FISHER_POSTERIOR_FACTOR)).all(), ratios
    assert checks[0]["well_identified"]
    files = write_design_report(result, tmp_path)
    payload = json.loads(files["json"].read_text())
    assert payload["ranking"][0]["name"] == "method4 10"
    assert payload["settings"]["seed"] == 0 and "numpy" in payload["settings"]["versions"]
    assert "Full-posterior checks" in files["markdown"].read_text()
    assert files["figures"][0].read_bytes()[:4] == b"\x89PNG"
    assert not list(tmp_path.glob(".design-*"))  # the temporary directory is gone


def test_rough_spectra_prior_scatters_around_the_spectrum():
    wl = (450.0, 550.0, 650.0)
    a, tau = np.array([0.05, 0.1, 0.2]), np.array([0.1, 0.08, 0.06])
    exact = DesignPrior(a=a, tau_per_um=tau, wavelengths=wl, spread=0.0)
    draws_a, draws_tau = exact.draw(5, np.random.default_rng(0))
    np.testing.assert_array_equal(draws_a, np.broadcast_to(a, (5, 3)))
    np.testing.assert_array_equal(draws_tau, np.broadcast_to(tau, (5, 3)))
    # log-normal scatter: the sd of log(draw / spectrum) is the spread; its estimate from 4000
    # draws has a relative error of 1/sqrt(8000) = 1.1 %, so 5 % is > 4 sigma
    rough = DesignPrior(a=a, tau_per_um=tau, wavelengths=wl, spread=0.3)
    draws_a, _ = rough.draw(4000, np.random.default_rng(0))
    np.testing.assert_allclose(np.log(draws_a / a).std(axis=0), 0.3, rtol=0.05)


def test_design_page_says_how_many_candidates_it_lists_and_shows_no_backticks(tmp_path):
    prior = DesignPrior(a=[0.1, 0.1], tau_per_um=[0.05, 0.05], wavelengths=(500.0, 600.0), spread=0.0)
    candidates = candidate_designs([5.0, 10.0, 20.0], ["black", "white", "grey:0.4"])
    result = rank_designs(candidates, prior, n_draws=1, seed=0)
    n = len(result.candidates)
    assert n > 5
    files = write_design_report(result, tmp_path, n_rows=5, command="bayespig design --out x")
    markdown, html = files["markdown"].read_text(), files["html"].read_text()
    assert f"The best 5 of {n} candidate sample sets (all {n} in design.json)." in markdown
    assert f"The best 5 of {n} candidate sample sets (all {n} in design.json)." in html
    assert f"Predicted relative posterior sd of a and tau of the best {min(12, n)} of {n} candidates." in markdown
    ranking = markdown.split("## Ranking")[1].split("\n## ")[0]
    assert sum(line.startswith("| ") for line in ranking.splitlines()) == 1 + 5  # header + 5 rows
    # the command is a code block, not backticks shown literally in the HTML
    assert "Generated by this command; rerun it to regenerate:\n\n```\nbayespig design --out x\n```" in markdown
    assert "`" not in html and "<pre>bayespig design --out x</pre>" in html
