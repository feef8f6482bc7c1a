"""numba kernels of the spring network's internal forces at (x, v): the Eq. 1 springs and the support.

Eq. 1, per connector i→j of rest length l0 (`SpringArrays`, one per edge): length l, unit axis u = (x_j − x_i)/l,
strain d = (l − l0)/l0, rate ḋ = (v_j − v_i)·u; tension T = λ1·d³ + λ2·d + μ·ḋ (N, 0 for a collapsed spring);
+T·u on node i and −T·u on node j.  Support (physics.tissue.organ_support): f_n −= k_n·(x_n − rest_n) + c_n·v_n on each
supported node n.

Array conventions: positions `x` and velocities `v` are (N, 3) float64 in m and m/s; the forces are added to
`f` (N, 3) in newtons.  The serial and the parallel spring kernels are separate functions (a cached dispatcher
must never be shared between a `parallel=True` and a serial build).  Users: the explicit frame
(physics.solver.explicit_kernels.add_forces, every substep) and the model's pull on held nodes with the implicit
integrator (which assembles its own forces and Jacobians in physics.solver.implicit_kernels).
`liver_sim.physics.solver.reference` is the plain-NumPy oracle of these kernels.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.physics.tissue.pairs import add_pair


class SpringArrays(NamedTuple):
    """One Eq. 1 connector per edge: node pairs (E,) int64, rest lengths (m), λ1 (N), λ2 (N), μ (N·s/m)."""

    node_i: np.ndarray
    node_j: np.ndarray
    rest_m: np.ndarray
    lambda1_n: np.ndarray
    lambda2_n: np.ndarray
    mu_ns_per_m: np.ndarray


@numba.njit(cache=True, inline="always")
def _spring_tension(x, v, i, j, rest, lambda1, lambda2, mu):
    """Eq. 1 tension (N) and unit axis i→j; tension 0 for a collapsed spring."""
    dx = x[j, 0] - x[i, 0]
    dy = x[j, 1] - x[i, 1]
    dz = x[j, 2] - x[i, 2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= 1e-12 * rest:
        return 0.0, 0.0, 0.0, 0.0
    ux, uy, uz = dx / length, dy / length, dz / length
    strain = (length - rest) / rest
    rate = (v[j, 0] - v[i, 0]) * ux + (v[j, 1] - v[i, 1]) * uy + (v[j, 2] - v[i, 2]) * uz
    tension = lambda1 * strain * strain * strain + lambda2 * strain + mu * rate
    return tension, ux, uy, uz


@numba.njit(cache=True, inline="always")
def _accumulate_springs(x, v, node_i, node_j, rest, lambda1, lambda2, mu, first, last, f):
    """Add the Eq. 1 forces of springs first..last−1 to f: +T·u on node i, −T·u on node j."""
    for s in range(first, last):
        i = node_i[s]
        j = node_j[s]
        t, ux, uy, uz = _spring_tension(x, v, i, j, rest[s], lambda1[s], lambda2[s], mu[s])
        add_pair(f, i, j, t * ux, t * uy, t * uz)


@numba.njit(cache=True)
def spring_forces_serial(x, v, node_i, node_j, rest, lambda1, lambda2, mu, f):
    """Add every spring's Eq. 1 force to f (one thread)."""
    _accumulate_springs(x, v, node_i, node_j, rest, lambda1, lambda2, mu, 0, node_i.shape[0], f)


@numba.njit(cache=True, parallel=True)
def spring_forces_parallel(x, v, node_i, node_j, rest, lambda1, lambda2, mu, partial, f):
    """As spring_forces_serial, on all threads: each of the len(partial) chunks of springs
    accumulates into its own (N, 3) slice of `partial`, then the slices are summed into f."""
    chunks = partial.shape[0]
    springs = node_i.shape[0]
    for c in numba.prange(chunks):
        own = partial[c]
        own[:] = 0.0
        _accumulate_springs(x, v, node_i, node_j, rest, lambda1, lambda2, mu,
                            c * springs // chunks, (c + 1) * springs // chunks, own)
    for n in numba.prange(f.shape[0]):
        for c in range(chunks):
            f[n, 0] += partial[c, n, 0]
            f[n, 1] += partial[c, n, 1]
            f[n, 2] += partial[c, n, 2]


@numba.njit(cache=True)
def support_forces(x, v, nodes, rest, stiffness, damping, f):
    """Add the support's spring-dampers to f: −k_n·(x_n − rest_n) − c_n·v_n on each supported node n
    (physics.tissue.organ_support)."""
    for s in range(nodes.shape[0]):
        n = nodes[s]
        for a in range(3):
            f[n, a] -= stiffness[s] * (x[n, a] - rest[s, a]) + damping[s] * v[n, a]
