"""TEMPORARY minimal recipes for the library build (helper "libcore").

Replaced at merge time by :mod:`bayespig.library.recipes` (helper "recipes"), whose interface
(LIBRARY-SPEC.md) this follows for what the build uses: :class:`Recipe` (``amounts``: pigment
-> mass fraction summing to 1, zeros dropped), :func:`film_recipes` and :func:`concentrations`.
Here concentrations are the mass fractions themselves (appendix A2 with equal densities and no
drying loss, :func:`bayespig.physics.mixtures.concentrations_from_mass_fractions`), unless
``densities`` are given.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..physics.mixtures import concentrations_from_mass_fractions

__all__ = ["Recipe", "concentrations", "film_recipes"]


@dataclasses.dataclass(frozen=True)
class Recipe:
    """Pigment -> mass fraction (summing to 1, zeros dropped)."""

    amounts: dict
    basis: str = "mass"

    @classmethod
    def from_composition(cls, composition):
        """From ``{"pigments": [...], "mass_ratios": [...]}`` (ratios normalised to fractions)."""
        pigments, ratios = composition["pigments"], np.asarray(composition["mass_ratios"], dtype=float)
        if len(pigments) != ratios.size or not np.isfinite(ratios).all() or (ratios < 0).any() or ratios.sum() <= 0:
            raise ValueError(f"composition: bad mass ratios {list(ratios)} for pigments {list(pigments)}")
        fractions = ratios / ratios.sum()
        return cls({str(p): float(f) for p, f in zip(pigments, fractions) if f > 0})


def film_recipes(sets):
    """Film id -> :class:`Recipe` from each set's ``metadata["composition"]``."""
    recipes = {}
    for film, measurements in sets.items():
        composition = (measurements.metadata or {}).get("composition")
        if composition is None:
            raise ValueError(f"film {film!r}: no recipe (metadata['composition'] is missing)")
        try:
            recipes[film] = Recipe.from_composition(composition)
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f"film {film!r}: {error}") from None
    return recipes


def concentrations(recipe, pigments, *, densities=None, drying=None):
    """The ``D_i`` of ``pigments`` (0 for those not in the recipe), shape (len(pigments),)."""
    fractions = np.array([recipe.amounts.get(p, 0.0) for p in pigments], dtype=float)
    density = 1.0 if densities is None else np.array([float(densities.get(p, 1.0)) for p in pigments])
    return concentrations_from_mass_fractions(fractions, paste_density=density)
