"""Argument checks shared by the baselines' update rules (ValueError naming the field)."""

from __future__ import annotations

import numpy as np


def check_positive_int(name: str, value) -> int:
    """``value`` as an int if it is an integer >= 1 (bools refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def as_parameter_vector(name: str, value) -> np.ndarray:
    """``value`` as a finite, non-empty 1-D float array (a copy)."""
    array = np.array(value, dtype=float)
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array}")
    return array
