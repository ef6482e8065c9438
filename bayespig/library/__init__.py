"""Pigment libraries: every pigment's constants from all the films that contain it (issue 17).

Between inference and studies in the data flow (it may import physics, table, data,
likelihood, inference, colorimetry; nothing below it imports it). :func:`build_library` builds
one from films of known recipes (:mod:`bayespig.library.build`: the joint sampler of
:mod:`bayespig.inference.shared` with the films' thicknesses as shared parameters, in stages);
:class:`PigmentLibrary` holds it, ``.save(path)`` writes one netCDF file and
:func:`load_library` reads it back. :func:`predict_paint` gives the colour of any recipe with
a credible ΔE00 region, :func:`match_paint` the recipe that matches a target.
"""

from .build import build_library, stage_plan
from .library import PigmentLibrary, load_library
from .match import PaintMatch, match_paint
from .predict import PaintPrediction, predict_paint

__all__ = ["PaintMatch", "PaintPrediction", "PigmentLibrary", "build_library", "load_library", "match_paint",
           "predict_paint", "stage_plan"]
