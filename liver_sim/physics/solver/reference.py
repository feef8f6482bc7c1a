"""Plain-NumPy oracle of one model step: the correctness reference and speed baseline of the kernels."""
from __future__ import annotations

import numpy as np

from liver_sim.physics.tissue.organ_support import SupportArrays
from liver_sim.physics.tissue.springs import SpringNetwork


def spring_forces(x: np.ndarray, v: np.ndarray, springs: SpringNetwork) -> np.ndarray:
    """Eq. 1 on every spring: node i gets +T·u, node j gets −T·u, u the unit axis i→j."""
    axis = x[springs.node_j] - x[springs.node_i]
    length = np.linalg.norm(axis, axis=1)
    unit = axis / length[:, None]
    strain = (length - springs.rest_length_m) / springs.rest_length_m
    rate = np.einsum("ij,ij->i", v[springs.node_j] - v[springs.node_i], unit)
    tension = springs.lambda1_n * strain ** 3 + springs.lambda2_n * strain + springs.mu_ns_per_m * rate
    edge_force = tension[:, None] * unit
    f = np.zeros_like(x)
    for k in range(3):
        f[:, k] = (np.bincount(springs.node_i, edge_force[:, k], minlength=len(x))
                   - np.bincount(springs.node_j, edge_force[:, k], minlength=len(x)))
    return f


def support_forces(x: np.ndarray, v: np.ndarray, support: SupportArrays) -> np.ndarray:
    """The support's −k_n·(x_n − rest_n) − c_n·v_n on each supported node (physics.tissue.organ_support)."""
    f = np.zeros_like(x)
    n = support.nodes
    np.add.at(f, n, -support.stiffness_n_per_m[:, None] * (x[n] - support.rest_m)
              - support.damping_ns_per_m[:, None] * v[n])
    return f


def step(x, v, springs, inv_mass, dt, environment_damping, gravity, integrator, support=None):
    """One step (Eq. 2 for 'explicit_euler', new velocity in the position update for 'symplectic_euler'),
    with the `support`'s ties if given.

    Returns new (x, v); nodes with inv_mass 0 are fixed.
    """
    f = spring_forces(x, v, springs)
    if support is not None:
        f += support_forces(x, v, support)
    free = (inv_mass > 0.0)[:, None]
    a = f * inv_mass[:, None] + np.asarray(gravity) - environment_damping * v
    v_new = np.where(free, v + dt * a, v)
    x_new = np.where(free, x + dt * (v_new if integrator == "symplectic_euler" else v), x)
    return x_new, v_new
