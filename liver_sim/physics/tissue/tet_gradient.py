"""The gradient of a nodal field over a linear tetrahedron, G = Σ_a u_a ⊗ g_a (u_a the field at node a, g_a the
gradient of its shape function): the deformation gradient F from the positions, Ḟ from the velocities, and the
directions' G of the solver's products.  Shared by the co-rotational law (fem_kernels) and the neo-Hookean one."""
from __future__ import annotations

import numba

#: Every node of an element counts in `tet_gradient`.
EVERY_NODE = (True, True, True, True)


@numba.njit(cache=True, inline="always")
def tet_gradient(values, tet, g, counts):
    """G = Σ_a values[tet[a]] ⊗ g_a over the nodes a with counts[a], as the 9-tuple (row (i, j) ↔ 3i + j)."""
    g00 = g01 = g02 = g10 = g11 = g12 = g20 = g21 = g22 = 0.0
    for a in range(4):
        if counts[a]:
            n = tet[a]
            px, py, pz = values[n, 0], values[n, 1], values[n, 2]
            hx, hy, hz = g[a, 0], g[a, 1], g[a, 2]
            g00 += px * hx
            g01 += px * hy
            g02 += px * hz
            g10 += py * hx
            g11 += py * hy
            g12 += py * hz
            g20 += pz * hx
            g21 += pz * hy
            g22 += pz * hz
    return g00, g01, g02, g10, g11, g12, g20, g21, g22
