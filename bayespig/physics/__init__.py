"""Radiative transfer of a pigmented paint layer: pure functions of arrays, no files, no sampling."""
