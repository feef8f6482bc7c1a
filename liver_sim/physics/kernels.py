"""numba kernels of one physics frame: springs (Eq. 1), penalty contact (Eq. 3), integration (Eq. 2).

Array conventions: positions `x` and velocities `v` are (N, 3) float64 in m and m/s;
forces accumulate in `f` (N, 3) in newtons.  The serial and the parallel spring
kernels are separate functions (a cached dispatcher must never be shared between
a `parallel=True` and a serial build).  `liver_sim.physics.reference` is the
plain-NumPy oracle of the spring and integration kernels.

`run_frame` takes the state arrays and five named tuples (numba reads their fields as
compile-time attributes, at no cost): the spring network (`SpringArrays`), the support
(`physics.support.SupportArrays`), the integration settings (`StepSettings`), the tool and its
contact candidates (`ToolState`) and the work arrays (`WorkArrays`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.geometry.closest_point import closest_point_on_triangle

TOOL_NONE = 0
TOOL_SPHERE = 1
TOOL_CAPSULE = 2
TOOL_BOX = 3


class SpringArrays(NamedTuple):
    """One Eq. 1 connector per edge: node pairs (E,) int64, rest lengths (m), λ1 (N), λ2 (N), μ (N·s/m)."""

    node_i: np.ndarray
    node_j: np.ndarray
    rest_m: np.ndarray
    lambda1_n: np.ndarray
    lambda2_n: np.ndarray
    mu_ns_per_m: np.ndarray


class StepSettings(NamedTuple):
    """Integration of one frame: `substeps` steps of `dt_s` (s), environmental damping c (1/s), gravity
    (3,) m/s², symplectic (True) or explicit Euler (False)."""

    dt_s: float
    substeps: int
    environment_damping_per_s: float
    gravity_m_s2: np.ndarray
    symplectic: bool


class ToolState(NamedTuple):
    """The tool over one frame and its contact candidates (Eq. 3).

    kind: TOOL_NONE, TOOL_SPHERE, TOOL_CAPSULE or TOOL_BOX; the core (a point, or the capsule's segment
    core_a–core_b, m) starts where given and moves at `velocity_m_s`; radius (m) of sphere and capsule;
    box axes (columns of a rotation) and half extents (m); penalty λ (N/m) and μ (N·s/m); `inward_point`:
    a point inside the liver (push direction of a node on the core); `candidates`: skin nodes near the
    tool; per candidate, `gap` (m), `point` and `direction` (the box's contact geometry, see
    box_tool_contacts).
    """

    kind: int
    core_a: np.ndarray
    core_b: np.ndarray
    radius_m: float
    axes: np.ndarray
    half_extents_m: np.ndarray
    velocity_m_s: np.ndarray
    stiffness_n_per_m: float
    damping_ns_per_m: float
    inward_point: np.ndarray
    candidates: np.ndarray
    gap: np.ndarray
    point: np.ndarray
    direction: np.ndarray


class WorkArrays(NamedTuple):
    """Scratch of one model: `force` (N, 3) N; with `parallel`, the spring kernel's per-thread
    `partial` sums (threads, N, 3)."""

    force: np.ndarray
    partial: np.ndarray
    parallel: bool


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
        f[i, 0] += t * ux
        f[i, 1] += t * uy
        f[i, 2] += t * uz
        f[j, 0] -= t * ux
        f[j, 1] -= t * uy
        f[j, 2] -= t * uz


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
    (physics.support)."""
    for s in range(nodes.shape[0]):
        n = nodes[s]
        for a in range(3):
            f[n, a] -= stiffness[s] * (x[n, a] - rest[s, a]) + damping[s] * v[n, a]


@numba.njit(cache=True)
def integrate(x, v, f, inv_mass, dt, environment_damping, gravity, symplectic):
    """One step of every free node (inv_mass > 0); fixed nodes (inv_mass = 0) do not move.

    a = f/m + g − c_env·v.  Explicit Euler (Eq. 2): v ← v + Δt·a, x ← x + Δt·v_old.
    Symplectic Euler: v ← v + Δt·a, x ← x + Δt·v_new.
    """
    for n in range(x.shape[0]):
        w = inv_mass[n]
        if w == 0.0:
            continue
        for k in range(3):
            a = f[n, k] * w + gravity[k] - environment_damping * v[n, k]
            if symplectic:
                v[n, k] += dt * a
                x[n, k] += dt * v[n, k]
            else:
                x[n, k] += dt * v[n, k]
                v[n, k] += dt * a


@numba.njit(cache=True)
def closest_point_on_segment(p, a, b):
    """Closest point to p on segment ab."""
    ab = b - a
    denom = ab @ ab
    if denom <= 0.0:
        return a.copy()
    t = min(1.0, max(0.0, ((p - a) @ ab) / denom))
    return a + t * ab


@numba.njit(cache=True)
def round_tool_contacts(x, v, candidates, core_a, core_b, shift, radius, inward_point, tool_velocity,
                        stiffness, damping, f):
    """Eq. 3 between a sphere (core_a == core_b) or capsule (segment core_a–core_b) moved by `shift`, and
    skin nodes.

    A candidate node closer than `radius` to the core has penetration δ = radius − distance and
    gets F = max(0, λ·δ + μ·δ̇)·k, k the unit vector from the core to the node (into the liver;
    toward `inward_point` if the node sits on the core).  Returns the total force on the liver
    (the tool feels its opposite).  Scalar arithmetic: no array is allocated per node or step.
    """
    ax, ay, az = core_a[0] + shift[0], core_a[1] + shift[1], core_a[2] + shift[2]
    ex, ey, ez = core_b[0] - core_a[0], core_b[1] - core_a[1], core_b[2] - core_a[2]
    length2 = ex * ex + ey * ey + ez * ez
    tx, ty, tz = 0.0, 0.0, 0.0
    for c in range(candidates.shape[0]):
        n = candidates[c]
        px, py, pz = x[n, 0] - ax, x[n, 1] - ay, x[n, 2] - az
        t = 0.0
        if length2 > 0.0:
            t = min(1.0, max(0.0, (px * ex + py * ey + pz * ez) / length2))
        dx, dy, dz = px - t * ex, py - t * ey, pz - t * ez
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        depth = radius - dist
        if depth <= 0.0:
            continue
        if dist > 1e-12:
            kx, ky, kz = dx / dist, dy / dist, dz / dist
        else:
            kx, ky, kz = inward_point[0] - x[n, 0], inward_point[1] - x[n, 1], inward_point[2] - x[n, 2]
            norm = math.sqrt(kx * kx + ky * ky + kz * kz)
            kx, ky, kz = kx / norm, ky / norm, kz / norm
        depth_rate = -(kx * (v[n, 0] - tool_velocity[0]) + ky * (v[n, 1] - tool_velocity[1])
                       + kz * (v[n, 2] - tool_velocity[2]))
        magnitude = max(0.0, stiffness * depth + damping * depth_rate)
        f[n, 0] += magnitude * kx
        f[n, 1] += magnitude * ky
        f[n, 2] += magnitude * kz
        tx += magnitude * kx
        ty += magnitude * ky
        tz += magnitude * kz
    return np.array([tx, ty, tz])


@numba.njit(cache=True)
def surface_gaps(x, skin, candidates, core_a, core_b, radius, gap, point, direction):
    """Per candidate skin triangle: closest points of the tool core and the triangle (alternating
    projection), gap = distance − radius (m, negative inside), the triangle point and the unit
    direction from the core to it (the triangle's inward normal if the core lies on it).
    """
    for c in range(candidates.shape[0]):
        corners = x[skin[candidates[c]]]
        s = closest_point_on_segment((corners[0] + corners[1] + corners[2]) / 3.0, core_a, core_b)
        q = np.array(closest_point_on_triangle((s[0], s[1], s[2]), corners)[0])
        for _ in range(4):
            s = closest_point_on_segment(q, core_a, core_b)
            q = np.array(closest_point_on_triangle((s[0], s[1], s[2]), corners)[0])
        delta = q - s
        dist = math.sqrt(delta @ delta)
        if dist > 1e-12:
            direction[c] = delta / dist
        else:
            normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            direction[c] = -normal / math.sqrt(normal @ normal)
        gap[c] = dist - radius
        point[c] = q


@numba.njit(cache=True)
def box_tool_contacts(x, v, candidates, centre, axes, half_extents, tool_velocity,
                      stiffness, damping, f, gap, point, direction):
    """Eq. 3 between a box (centre, axes = columns of a rotation matrix, half extents) and skin nodes.

    A node inside the box is pushed out through the nearest face: δ = h_a − |q_a| on the axis a of
    least depth, k = ±axis a.  Writes each candidate node's gap (m; distance to the box outside,
    −δ inside), position and k; returns the total force on the liver.
    """
    total = np.zeros(3)
    for c in range(candidates.shape[0]):
        n = candidates[c]
        local = axes.T @ (x[n] - centre)
        outside = np.maximum(np.abs(local) - half_extents, 0.0)
        point[c] = x[n]
        if outside.max() > 0.0:
            gap[c] = math.sqrt(outside @ outside)
            direction[c] = axes @ (np.sign(local) * outside) / gap[c]
            continue
        depths = half_extents - np.abs(local)
        axis = np.argmin(depths)
        k = axes[:, axis] * (1.0 if local[axis] >= 0.0 else -1.0)
        gap[c] = -depths[axis]
        direction[c] = k
        depth_rate = -(k @ (v[n] - tool_velocity))
        force = max(0.0, stiffness * depths[axis] + damping * depth_rate) * k
        f[n] += force
        total += force
    return total


@numba.njit(cache=True, inline="always")
def add_forces(x, v, external_force, springs, support, tool, work, shift, contact):
    """work.force ← external force + Eq. 1 spring forces + the support + Eq. 3 contact of the tool core moved
    by `shift`; the contact force on the liver (N) goes to `contact` (left alone without a tool)."""
    f = work.force
    f[:] = external_force
    s = springs
    if work.parallel:
        spring_forces_parallel(x, v, s.node_i, s.node_j, s.rest_m, s.lambda1_n, s.lambda2_n, s.mu_ns_per_m,
                               work.partial, f)
    else:
        spring_forces_serial(x, v, s.node_i, s.node_j, s.rest_m, s.lambda1_n, s.lambda2_n, s.mu_ns_per_m, f)
    support_forces(x, v, support.nodes, support.rest_m, support.stiffness_n_per_m, support.damping_ns_per_m, f)
    t = tool
    if t.kind == TOOL_BOX:
        contact[:] = box_tool_contacts(x, v, t.candidates, t.core_a + shift, t.axes, t.half_extents_m,
                                       t.velocity_m_s, t.stiffness_n_per_m, t.damping_ns_per_m, f, t.gap, t.point,
                                       t.direction)
    elif t.kind != TOOL_NONE:
        contact[:] = round_tool_contacts(x, v, t.candidates, t.core_a, t.core_b, shift, t.radius_m, t.inward_point,
                                         t.velocity_m_s, t.stiffness_n_per_m, t.damping_ns_per_m, f)


@numba.njit(cache=True, nogil=True)
def run_frame(x, v, inv_mass, external_force, springs, support, settings, tool, work):
    """`settings.substeps` steps of the model; the tool core moves at `tool.velocity_m_s` from its start.

    Runs without the GIL, so a node's executor thread keeps delivering messages meanwhile.
    `external_force` (N, 3) is added to every node each step.  Returns the contact force on the liver
    at the last substep (N); the tool's reaction is its opposite.  For a box, the candidates' contact
    geometry of the last substep is left in tool.gap/point/direction.
    """
    contact = np.zeros(3)
    shift = np.zeros(3)
    dt = settings.dt_s
    for step in range(settings.substeps):
        for k in range(3):
            shift[k] = tool.velocity_m_s[k] * ((step + 1) * dt)
        add_forces(x, v, external_force, springs, support, tool, work, shift, contact)
        integrate(x, v, work.force, inv_mass, dt, settings.environment_damping_per_s, settings.gravity_m_s2,
                  settings.symplectic)
    return contact
