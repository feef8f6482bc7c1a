"""Argument checks shared by the cores (no ROS): each returns the checked value or raises ValueError naming it."""
from __future__ import annotations

import math

import numpy as np


def positive(value, name: str) -> float:
    """`value` as a float if finite and > 0, else ValueError naming `name`."""
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return value


def non_negative(value, name: str) -> float:
    """`value` as a float if finite and ≥ 0, else ValueError naming `name`."""
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return value


def vector3(value, name: str) -> np.ndarray:
    """`value` as a new, read-only float64 3-vector if finite, else ValueError naming `name`."""
    vec = np.array(value, dtype=np.float64)
    if vec.shape != (3,) or not np.isfinite(vec).all():
        raise ValueError(f"{name} must be finite and of shape (3,), got {value!r}")
    vec.setflags(write=False)
    return vec
