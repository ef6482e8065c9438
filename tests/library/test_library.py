"""The pigment library's own records (no build here: the stages are written by hand)."""

import numpy as np
import pytest

from bayespig.library.library import PigmentLibrary


def _library(stages, base_pigments=None):
    pigments = ("Red", "White", "Black")
    provenance = {"base_library": None if base_pigments is None else {"pigments": list(base_pigments), "films": []}}
    return PigmentLibrary(model="radiative-transfer", pigments=pigments, wavelength_nm=np.array([500.0]),
                          constants=np.zeros((2, 1, 3, 2)), constant_names=("a", "log_sigma"),
                          thickness_prior=(0.0, 0.5), films=(), film_ids=(), thickness=np.zeros((2, 0)),
                          densities=None, model_error=None, provenance=provenance, stages=tuple(stages))


def _stage(pigments, capped):
    return {"stage": 1, "pigments": list(pigments), "films": [], "max_steps_reached": capped}


@pytest.mark.parametrize("own_capped, base_capped", [(False, False), (False, True), (True, False), (True, True)])
def test_a_capped_stage_is_told_apart_from_a_capped_base_stage(own_capped, base_capped):
    # a build on a base library lists its own stages and then the base's (bayespig.library.build)
    library = _library([_stage(["Red"], own_capped), _stage(["Black", "White"], base_capped)], ("White", "Black"))
    assert library.step_cap_reached() == (own_capped or base_capped)
    assert library.step_cap_reached(inherited=False) == own_capped


def test_without_a_base_library_every_stage_is_the_library_s_own():
    library = _library([_stage(["Black", "White"], True), _stage(["Red"], False)])
    assert library.step_cap_reached(inherited=False)
    assert not _library([_stage(["Black", "White"], False)]).step_cap_reached(inherited=False)
