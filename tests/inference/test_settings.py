"""InferenceSettings: checks and the move mixture."""

import json

import pytest

from bayespig.inference import (
    InferenceSettings,
)


@pytest.mark.parametrize("kwargs, match", [
    ({"n_ensembles": 1}, "n_ensembles"),
    ({"moves": "gibbs"}, "moves"),
    ({"max_steps": 10, "min_steps": 20}, "max_steps"),
    ({"n_walkers": 0}, "n_walkers"),
])
def test_bad_settings_are_clear_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        InferenceSettings(**kwargs)


def test_gaussian_moves_need_more_walkers_than_parameters():
    """The Gaussian proposal's covariance comes from n_walkers / 2 walkers: "auto" falls back
    to DE moves when they do not outnumber the parameters by two; an explicit choice errs."""
    settings = InferenceSettings()  # 16 walkers: 8 complementary
    assert settings.move_mixture_for(6) == settings.move_mixture
    assert all(kind != "gaussian" for kind, _ in settings.move_mixture_for(7))
    with pytest.raises(ValueError, match="= 18 for 7 parameters"):
        InferenceSettings(moves="gaussian").move_mixture_for(7)
    assert json.loads(settings.to_json(7))["move_mixture"] == [["de", 0.8], ["snooker", 0.2]]
