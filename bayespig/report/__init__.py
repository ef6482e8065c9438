"""Uncertainty reports: figures, colour and HTML/Markdown/CSV/JSON output of a posterior.

:func:`write_report` is the entry point; :mod:`bayespig.report.quantities` computes the
numbers (usable on their own), :mod:`bayespig.report.figures` draws them (matplotlib, Agg),
:mod:`bayespig.report.document` renders the page twice (HTML with embedded figures, Markdown).
"""

from .quantities import FilmDesign, default_unmeasured_films
from .write import ReportResult, load_posterior, write_report

__all__ = ["FilmDesign", "ReportResult", "default_unmeasured_films", "load_posterior", "write_report"]
