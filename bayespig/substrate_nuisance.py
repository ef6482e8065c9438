"""Substrate albedo as a nuisance parameter (moved to :mod:`bayespig.inference.card_factors`).

The card factors are one spec of the joint machinery for parameters shared over wavelengths,
:mod:`bayespig.inference.shared`; this module keeps the old import path.
"""

from .inference.card_factors import (
    DEFAULT_RELATIVE_SD,
    FACTOR_PRIOR_SDS,
    CardFactorLogPosterior,
    CardFactors,
    ConditionalBlocksMove,
    card_indices,
)

__all__ = [
    "DEFAULT_RELATIVE_SD",
    "FACTOR_PRIOR_SDS",
    "CardFactorLogPosterior",
    "CardFactors",
    "ConditionalBlocksMove",
    "card_indices",
]
