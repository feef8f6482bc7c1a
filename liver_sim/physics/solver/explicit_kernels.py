"""numba kernels of one explicit frame (Eq. 2, or symplectic Euler): forces, then integration, per substep.

Each of `settings.substeps` steps of Δt: f = f_ext + the Eq. 1 springs and the support
(physics.tissue.spring_law) + the Eq. 3 contact of the tool's probes moved along its velocity
(physics.contact.kernels.add_contact_forces); a = f/m + g − c_env·v on every free node (inv_mass > 0;
fixed and held nodes do not move).  Explicit Euler (Eq. 2): x ← x + Δt·v, v ← v + Δt·a; symplectic
Euler: v ← v + Δt·a, x ← x + Δt·v_new.  `max_speed` is the divergence guard's measure of a state (the
model checks it after every frame, whatever the integrator).  `liver_sim.physics.solver.reference` is the
plain-NumPy oracle of the integration.

Array conventions: positions `x` and velocities `v` are (N, 3) float64 in m and m/s; forces accumulate
in `f` (N, 3) in newtons.

`run_frame` takes the state arrays and five named tuples (numba reads their fields as
compile-time attributes, at no cost): the spring network (`physics.tissue.spring_law.SpringArrays`), the support
(`physics.tissue.organ_support.SupportArrays`), the integration settings (`StepSettings`), the tool and its
contact candidates (`physics.contact.kernels.ToolSweep`) and the work arrays (`WorkArrays`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.physics.contact.kernels import TOOL_NONE, add_contact_forces
from liver_sim.physics.tissue.organ_support import support_forces
from liver_sim.physics.tissue.spring_law import spring_forces_parallel, spring_forces_serial


class StepSettings(NamedTuple):
    """Integration of one frame: `substeps` steps of `dt_s` (s), environmental damping c (1/s), gravity
    (3,) m/s², symplectic (True) or explicit Euler (False)."""

    dt_s: float
    substeps: int
    environment_damping_per_s: float
    gravity_m_s2: np.ndarray
    symplectic: bool


class WorkArrays(NamedTuple):
    """Scratch of one model: `force` (N, 3) N; with `parallel`, the spring kernel's per-thread
    `partial` sums (threads, N, 3)."""

    force: np.ndarray
    partial: np.ndarray
    parallel: bool


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
def max_speed(x, v):
    """The largest node speed |v| (m/s); NaN when a position or velocity is not finite."""
    top = 0.0
    for n in range(x.shape[0]):
        s2 = v[n, 0] * v[n, 0] + v[n, 1] * v[n, 1] + v[n, 2] * v[n, 2]
        if not (math.isfinite(s2) and math.isfinite(x[n, 0] + x[n, 1] + x[n, 2])):
            return math.nan
        top = max(top, s2)
    return math.sqrt(top)


@numba.njit(cache=True, inline="always")
def add_forces(x, v, external_force, springs, support, tool, work, shift, dt, contact):
    """work.force ← external force + Eq. 1 spring forces + the support + Eq. 3 contact of the tool's probes moved
    by `shift`; the contact force on the liver (N) goes to `contact` (left alone without a tool)."""
    f = work.force
    f[:] = external_force
    if work.parallel:
        spring_forces_parallel(x, v, springs, work.partial, f)
    else:
        spring_forces_serial(x, v, springs, f)
    support_forces(x, v, support.nodes, support.rest_m, support.stiffness_n_per_m, support.damping_ns_per_m, f)
    if tool.kind != TOOL_NONE:
        contact[:] = add_contact_forces(x, v, tool, shift, dt, f)


@numba.njit(cache=True, nogil=True)
def run_frame(x, v, inv_mass, external_force, springs, support, settings, tool, work):
    """`settings.substeps` steps of the model; the tool core moves at `tool.velocity_m_s` from its start.

    Runs without the GIL, so a node's executor thread keeps delivering messages meanwhile.
    `external_force` (N, 3) is added to every node each step.  Returns the contact force on the liver
    at the last substep (N); the tool's reaction is its opposite.  The probes' contact geometry of the
    last substep is left in the tool's arrays.
    """
    contact = np.zeros(3)
    shift = np.zeros(3)
    dt = settings.dt_s
    for step in range(settings.substeps):
        for k in range(3):
            shift[k] = tool.velocity_m_s[k] * ((step + 1) * dt)
        add_forces(x, v, external_force, springs, support, tool, work, shift, dt, contact)
        integrate(x, v, work.force, inv_mass, dt, settings.environment_damping_per_s, settings.gravity_m_s2,
                  settings.symplectic)
    return contact
