"""Studies built on the fits and the posterior: robustness of the paper's methods (section 4)."""

from .robustness import (
    PAPER_A0,
    PAPER_A_RMS,
    PAPER_METHODS,
    PAPER_TAU0,
    PAPER_TAU_RMS,
    RobustnessGrid,
    RobustnessResult,
    plot_robustness_map,
    robustness_map,
    robustness_study,
    write_paper_tables,
)

__all__ = [
    "PAPER_A0",
    "PAPER_A_RMS",
    "PAPER_METHODS",
    "PAPER_TAU0",
    "PAPER_TAU_RMS",
    "RobustnessGrid",
    "RobustnessResult",
    "plot_robustness_map",
    "robustness_map",
    "robustness_study",
    "write_paper_tables",
]
