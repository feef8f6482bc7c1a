"""Checked values of a message: finite arrays and floats, unit quaternions, colours; a ValueError names the field."""
from __future__ import annotations

import math

import numpy as np
from std_msgs.msg import ColorRGBA


def finite_array(value, shape: tuple, name: str, dtype=np.float64) -> np.ndarray:
    """`value` as a finite array of `shape` (-1 = any length) and `dtype`, or ValueError naming `name`."""
    with np.errstate(over="ignore", invalid="ignore"):
        arr = np.asarray(value, dtype=dtype)
    if arr.ndim != len(shape) or any(want not in (-1, got) for want, got in zip(shape, arr.shape)):
        wanted = ", ".join("N" if want == -1 else str(want) for want in shape)
        raise ValueError(f"{name} must have shape ({wanted}), got {arr.shape}")
    finite = np.isfinite(arr)
    if not finite.all():
        first = np.argwhere(~finite)[0].tolist()
        raise ValueError(f"{name} must be finite ({np.dtype(dtype).name}), got {arr[tuple(first)]} at index {first}")
    return arr


def unit_quaternion(value, name: str) -> np.ndarray:
    """A finite, non-zero (x, y, z, w) quaternion, normalised, or ValueError naming `name`.

    Scaled by its largest component before the norm, so that neither huge (1e200) nor tiny (1e-200)
    components overflow or underflow into a zero quaternion.  Four finite floats (a decoded message, a (4,)
    array) take a scalar path: a 1 kHz loop calls this for every pose."""
    if type(value) is tuple or (type(value) is np.ndarray and value.shape == (4,)):
        components = tuple(map(float, value))
        if len(components) == 4 and all(map(math.isfinite, components)):
            largest = max(map(abs, components))
            if largest > 0.0:
                x, y, z, w = (c / largest for c in components)
                norm = math.sqrt(x * x + y * y + z * z + w * w)
                return np.array((x / norm, y / norm, z / norm, w / norm))
    q = finite_array(value, (4,), name)
    largest = float(np.abs(q).max())
    if not largest > 0.0:
        raise ValueError(f"{name} must be a non-zero quaternion (x, y, z, w), got {q.tolist()}")
    q = q / largest
    return q / float(np.linalg.norm(q))


def finite_floats(values: tuple, shape: tuple, name: str) -> tuple:
    """`values` unchanged when all are finite floats; else the ValueError of :func:`finite_array` naming `name`."""
    if not all(map(math.isfinite, values)):
        finite_array(values, shape, name)
    return values


def colour_msg(rgba) -> ColorRGBA:
    """ColorRGBA of a finite (r, g, b, a)."""
    r, g, b, a = finite_array(rgba, (4,), "colour").tolist()
    return ColorRGBA(r=r, g=g, b=b, a=a)
