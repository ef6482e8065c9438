"""The colour-prediction report from held-out predictions of known ΔE00 (no library built here)."""

import re

import numpy as np

from bayespig.library.validation import FilmPrediction
from bayespig.studies.colour_prediction import MODELS, ColourPredictionStudy, class_medians, colour_prediction_report

WL = np.arange(400.0, 701.0, 10.0)
RT, KM = MODELS
#: (film, class, recipe) of the hand-made study.
FILMS = (("06B", "white tint", {"Vermillion": 0.1, "ZincWhite": 0.9}),
         ("06C", "white tint", {"Vermillion": 0.5, "ZincWhite": 0.5}),
         ("06D", "black shade", {"Vermillion": 0.99, "BoneBlack": 0.01}))


def _prediction(film_id, model, recipe, dE, dE_card, dE_unknown, h_card=(0.9, 1.1), converged=True,
                own_converged=True):
    residuals = np.zeros((2, WL.size))
    residuals[:, 5] = 0.1  # worst band 450 nm
    return FilmPrediction(film_id, model, recipe, (f"{film_id}_b", f"{film_id}_w"), 1.0, dE, dE_unknown, residuals,
                          np.ones((2, 4, WL.size)) * 0.3, np.full((2, WL.size), 0.3), dict(recipe), 0.5, 1.0,
                          converged, 450.0, h_card, dE_card, own_converged)


def _study():
    # ΔE00 over (black, white): one thickness, one per card, thickness unknown
    values = {RT: ((1.0, 2.0), (3.0, 4.0), (5.0, 6.0)), KM: ((2.0, 2.0), (4.0, 4.0), (6.0, 6.0))}
    predictions = []
    for model, rows in values.items():
        for (film_id, _, recipe), dE in zip(FILMS, rows):
            per_card = tuple(d / 2 for d in dE)
            # one film whose two thicknesses are far apart (counted in the report)
            h_card = (0.29, 6.4) if (model, film_id) == (RT, "06D") else (0.9, 1.1)
            # the radiative-transfer library without 06D reached its step cap in its own stage; those
            # without 06B (radiative transfer) and 06C (Kubelka-Munk) only in the base stage they share
            own_capped = (model, film_id) == (RT, "06D")
            base_capped = (model, film_id) in ((RT, "06B"), (KM, "06C"))
            predictions.append(_prediction(film_id, model, recipe, dE, per_card, tuple(d + 1 for d in dE), h_card,
                                           converged=not (own_capped or base_capped),
                                           own_converged=not own_capped))
    return ColourPredictionStudy(tuple(predictions), {f: c for f, c, _ in FILMS}, {RT: (5, 6), KM: (6, 6)},
                                 {(m, f): (True, True) for m in MODELS for f, _, _ in FILMS},
                                 {(m, f): (1.0, 1.0) for m in MODELS for f, _, _ in FILMS}, WL,
                                 {"seed": 0, "n_draws": 4, "instrument": "8d-sce", "level": 0.9,
                                  "noise_scale": "measured", "seconds": 1800.0,
                                  "sampler": {"target_ess": 100.0, "max_steps": 6000, "n_walkers": 20},
                                  "versions": {"bayespig": "0.1.0", "python": "3.11.7"}})


def test_class_medians_pool_both_cards_of_every_film_of_a_class():
    study = _study()
    assert class_medians(study, RT) == {"white tint": 2.5, "black shade": 5.5, "overall": 3.5}
    assert class_medians(study, RT, "per card") == {"white tint": 1.25, "black shade": 2.75, "overall": 1.75}
    assert class_medians(study, KM, "unknown") == {"white tint": 4.0, "black shade": 7.0, "overall": 5.0}


def test_the_report_states_every_thickness_variant_and_the_goals():
    text = colour_prediction_report(_study())
    assert "| fitted | radiative-transfer | 2.50 | 5.50 | 3.50 |" in text
    assert "| per card | kubelka-munk | 1.50 | 3.00 | 2.00 |" in text
    assert "| unknown | radiative-transfer | 3.50 | 6.50 | 4.50 |" in text
    # white tints 2.5 / 3.0, black shades 5.5 / 6.0: neither ratio <= 0.8; overall 3.5 > 2.0
    assert "white tints: bayespig / Kubelka-Munk = 0.83 (goal <= 0.8) — not met" in text
    assert "black shades: bayespig / Kubelka-Munk = 0.92 (goal <= 0.8) — not met" in text
    assert "overall: bayespig 3.50 (goal <= 2.0) — not met" in text
    assert "With one thickness per card, bayespig / Kubelka-Munk: white tints 0.83, black shades 0.92; overall " \
           "bayespig 1.75." in text
    assert "differ by more than a factor 2 for 1 of 3 films (bayespig) and 0 of 3 (Kubelka-Munk)" in text
    assert "| radiative-transfer | 5 / 6 | 83% |" in text
    assert text.rstrip().endswith("every build's sampler: target_ess 100.0, max_steps 6000; 30 min; bayespig 0.1.0, "
                                  "Python 3.11.7.")
    row = next(line for line in text.splitlines() if line.startswith("| 06D |"))
    assert "2.50 / 3.00 (0.29, 6.4); 3.00 / 3.00 (0.9, 1.1)" in row
    assert re.search(r"\| 06D \| black shade \| Vermillion 0\.990, BoneBlack 0\.010 \| 5\.00 / 6\.00 \| 6\.00 / 6\.00 \|",
                     text)



def test_the_report_counts_the_capped_builds_and_their_films_median():
    text = colour_prediction_report(_study())
    # RT: 06D capped in its own stage (5.0, 6.0); converged 06B (1.0, 2.0) and 06C (3.0, 4.0) -> median 2.5
    # (06B's build capped in the base stage only: counted as capped, not as capped in its own stages)
    assert "| radiative-transfer | 2 of 3 | 1 of 3 | 2.50 (2 films) | 5.50 (1 film) |" in text
    # KM: 06C capped in the shared base stage only: counted as capped, its own stages converged
    assert "| kubelka-munk | 1 of 3 | 0 of 3 | 4.00 (3 films) | — |" in text
    worst = {line[4:7]: line for line in text.splitlines() if line.startswith("- **")}
    assert worst["06D"].endswith("its library did not converge (its own stages reached the step cap).")
    assert worst["06B"].endswith("only the shared base stage of its library reached the step cap.")
    assert "step cap" not in worst["06C"]
