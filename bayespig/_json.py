"""JSON-ready values for the summaries bayespig writes."""

from __future__ import annotations

import numpy as np

__all__ = ["jsonable"]


def jsonable(value):
    """``value`` with numpy scalars and arrays as Python numbers and lists, non-finite floats as None.

    Dict keys become strings; lists, tuples and arrays are converted element by element.
    """
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        value = float(value)
        return value if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value
