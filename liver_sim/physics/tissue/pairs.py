"""The equal and opposite pair of a spring (or of its stiffness acting on a vector) on its two nodes, for the
numba kernels: out[i] += a, out[j] −= a."""
from __future__ import annotations

import numba


@numba.njit(cache=True, inline="always")
def add_pair(out, i, j, ax, ay, az):
    """out[i] += (ax, ay, az); out[j] −= (ax, ay, az)."""
    out[i, 0] += ax
    out[i, 1] += ay
    out[i, 2] += az
    out[j, 0] -= ax
    out[j, 1] -= ay
    out[j, 2] -= az
