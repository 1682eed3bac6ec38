"""Conversion of results to JSON (numpy arrays and scalars to plain lists and numbers)."""

import numpy as np


def jsonable(value):
    """``default=`` hook of :func:`json.dumps` for numpy values."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def json_line(record) -> str:
    """One line of strict JSON; NaN and infinities (never valid JSON) become null."""
    import json

    return json.dumps(_finite(record), allow_nan=False, default=jsonable)


def _finite(value):
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    if isinstance(value, np.ndarray):
        return _finite(value.tolist())
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value
