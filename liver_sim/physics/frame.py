"""A frame of the liver (paper §2): a short list of stages over (structure, state, tools), each entered once, as
MuJoCo MJX's `step()`.

`step(structure, state, tools, poses)` advances one frame (1/frame_rate_hz s, `substeps` steps) with each tool at
its pose: `use_before` (each tool's use: grasp or let go) → `move_held` (the held nodes where their tool holds
them) → `sweep_tools` (each tool's probes and candidate triangles over the frame) → `integrate` (the implicit
step with every tool's contact rows, physics.contact.rows, or for one tool the explicit kernels,
physics.solver.explicit_kernels.run_frame) → `held_pulls` (what a holding tool feels) → `guard` (divergence:
the state back to rest) → `tear_stage` → `local_models` (each tool's for the haptic loop) → `cut_stage` (along a
stroke that ended).  Tears and cuts take one path (`change_topology`): the new structure and state are built
beside the old ones and replace them only when both are whole.

Two tools meet only through the tissue: neither collides with the other (they pass through each other), a node
held by one is not grasped by another, and a tool pressing a node another holds feels that node where the holding
tool puts it (the holding tool feels the tissue's pull on the node, not that press).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact.kernels import TOOL_NONE, ToolSweep
from liver_sim.physics.contact.rows import Contacts, contact_force_n, joined, pushing, split
from liver_sim.physics.contact.tool_geometry import (
    ToolPose,
    contact_rows,
    probe_contacts,
    update_multipliers,
)
from liver_sim.physics.solver.explicit_kernels import max_speed, run_frame
from liver_sim.physics.state import State, ToolState, carried_state, rest_state
from liver_sim.physics.structure import Structure, build_structure
from liver_sim.physics.tissue.organ_support import support_forces
from liver_sim.physics.tissue.spring_law import spring_forces_serial
from liver_sim.physics.tissue.springs import estimate_stable_time_step
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import held_positions, release
from liver_sim.physics.topology.change import NodeState, TopologyChange, carry_over, separate_faces
from liver_sim.physics.topology.cutting import cut_along_path
from liver_sim.physics.topology.tearing import duplication_change, faces_to_tear


@dataclass(frozen=True)
class FrameResult:
    """What one frame produced: simulation time (s), the force on each tool (N) and its local model, in the
    model's order of tools, divergence, the topology changes it made in order ('torn', 'cut'; each moved
    `Structure.version` on), why a tear or a cut failed (the model is then as it was), and what the tools' use did
    ('grasped …', 'released …', after 'NAME: ' for a named tool).  `tool_force_n` and `local_model` are the
    first tool's (the only one by default)."""

    time_s: float
    tool_forces_n: tuple[np.ndarray, ...]
    local_models: tuple[LocalModel, ...]
    divergence: str | None
    topology_changes: tuple[str, ...] = ()
    topology_failures: tuple[str, ...] = ()
    tool_events: tuple[str, ...] = ()

    @property
    def tool_force_n(self) -> np.ndarray:
        return self.tool_forces_n[0]

    @property
    def local_model(self) -> LocalModel:
        return self.local_models[0]

    @property
    def topology_changed(self) -> bool:
        return bool(self.topology_changes)


def apply_change(structure: Structure, state: State, change: TopologyChange) -> tuple[Structure, State]:
    """The structure and state after a tear or a cut: the new mesh, masses and node state
    (topology.carry_over, which checks the change first), the springs and support rebuilt on it
    (structure.build_structure, one version on), the state carried over (state.carried_state).  The given
    structure and state are left as they were, whatever raises."""
    nodes = NodeState(state.positions, state.velocities, state.external_forces_n, structure.masses_kg,
                      structure.fixed_nodes)
    params = structure.params
    mesh, nodes = carry_over(change, nodes, structure.mesh.source, params.density_kg_m3,
                             params.min_node_mass_fraction)
    changed = build_structure(mesh, params, change.capsule_triangles, nodes.masses_kg, nodes.fixed_nodes,
                              structure.parallel, structure.version + 1)
    return changed, carried_state(changed, state, nodes)


def step(structure: Structure, state: State, tools: Sequence[Tool],
         poses: Sequence[ToolPose | None]) -> tuple[Structure, State, FrameResult]:
    """One frame with each tool at its pose (None: away), in the order of `tools`: the stages of the module
    docstring, each once.  Returns the structure and state after it (new ones after a tear or a cut, or a
    divergence's reset to rest) and what it produced."""
    events = use_before(structure, state, tools, poses)
    holding = move_held(structure, state, poses)
    sweeps = sweep_tools(structure, state, tools, poses, holding)
    liver_forces, rows = integrate(structure, state, sweeps, structure.params.substeps)
    held_pulls(structure, state, holding, liver_forces)
    state.time_s += structure.frame_period_s
    diverged = divergence(structure, state)
    changes, failures = [], []
    if diverged is not None:
        state = rest_state(structure, len(tools), state.time_s, state.external_forces_n)
        models = tuple(LocalModel.invalid() for _ in tools)
        tool_forces = tuple(np.zeros(3) for _ in tools)
    else:
        if structure.params.tearing:
            structure, state = change_topology(structure, state, "torn", tear_change, changes, failures,
                                               "tear failed")
        models = local_models(structure, state, tools, poses, liver_forces, holding, rows)
        tool_forces = tuple(-force for force in liver_forces)
    structure, state = cut_stage(structure, state, tools, models, changes, failures)
    return structure, state, FrameResult(state.time_s, tool_forces, models, diverged, tuple(changes),
                                         tuple(failures), events)


def label(tools: Sequence[Tool], k: int, text: str) -> str:
    """`text` of tool k, after its name when it has one."""
    return f"{tools[k].name}: {text}" if tools[k].name else text


def use_before(structure: Structure, state: State, tools: Sequence[Tool],
               poses: Sequence[ToolPose | None]) -> tuple[str, ...]:
    """Each tool's use before a frame (ToolUse.before_frame): grasp what it touches, or let go; what they did."""
    events = []
    for k, (tool, pose) in enumerate(zip(tools, poses)):
        decision = tool.use.before_frame(state.tools[k], pose)
        if decision == "grasp":
            events.append(label(tools, k, f"grasped {grasp(structure, state, tools, k, pose)} skin node(s)"))
        elif decision == "release":
            let_go(structure, state, k)
            events.append(label(tools, k, "released the grasped nodes"))
    return tuple(events)


def grasp(structure: Structure, state: State, tools: Sequence[Tool], k: int, pose: ToolPose) -> int:
    """Let tool k hold the skin nodes it touches at `pose` (ToolUse.grasp; none another tool holds), from the next
    frame on moved with it, kinematically, until it lets go; returns how many."""
    others = [t.held_nodes for j, t in enumerate(state.tools) if j != k and t.holding]
    skin_nodes = structure.mesh.skin_nodes
    free = np.setdiff1d(skin_nodes, np.concatenate(others)) if others else skin_nodes
    nodes = tools[k].use.grasp(state.tools[k], tools[k].shape, pose, state.positions, free)
    state.hold(structure)
    return len(nodes)


def let_go(structure: Structure, state: State, k: int | None = None) -> None:
    """Let go of the nodes tool k holds (None: every tool's)."""
    for j, tool in enumerate(state.tools):
        if k is None or j == k:
            release(tool)
    state.hold(structure)


def move_held(structure: Structure, state: State, poses: Sequence[ToolPose | None]) -> list[bool]:
    """Each tool holding nodes moves them to where it holds them, at the speed that takes them there in one frame,
    instead of pushing; whether each tool holds (it is away: it does not)."""
    holding = [pose is not None and tool.holding for tool, pose in zip(state.tools, poses)]
    for tool, pose, holds in zip(state.tools, poses, holding):
        if holds:
            nodes, held = tool.held_nodes, held_positions(tool, pose)
            state.velocities[nodes] = (held - state.positions[nodes]) / structure.frame_period_s
            state.positions[nodes] = held
    return holding


def sweep_tools(structure: Structure, state: State, tools: Sequence[Tool], poses: Sequence[ToolPose | None],
                holding: Sequence[bool]) -> list[ToolSweep]:
    """Each tool over the frame (Tool.sweep); a holding tool presses nothing."""
    return [tool.sweep(structure, state.positions, tool_state, None if holds else pose)
            for tool, tool_state, pose, holds in zip(tools, state.tools, poses, holding)]


def integrate(structure: Structure, state: State, tools: Sequence[ToolSweep],
              substeps: int) -> tuple[list[np.ndarray], list[Contacts]]:
    """`substeps` steps of the springs, support, loads and the tools' contacts (Eq. 1–3) by the structure's
    integrator, in place on the state; returns each tool's contact force on the liver at the end (N) and its
    contact rows of the last step (none for the explicit integrators, which take one tool), and leaves the probes'
    contact geometry at the end in the tools' arrays."""
    if structure.implicit:
        return implicit_frame(structure, state, tools, substeps)
    if len(tools) != 1:
        raise ValueError(f"{structure.params.integrator} steps one tool's contact, not {len(tools)}")
    return [run_frame(state.positions, state.velocities, state.inv_mass, state.external_forces_n,
                      structure.spring_arrays, structure.support, structure.step_settings._replace(substeps=substeps),
                      tools[0], structure.work)], [Contacts.none()]


def implicit_frame(structure: Structure, state: State, tools: Sequence[ToolSweep],
                   substeps: int) -> tuple[list[np.ndarray], list[Contacts]]:
    """`substeps` backward-Euler steps, each with every tool's contacts with the skin, taken where its probes are at
    the end of the step (contact.tool_geometry.contact_rows), in one set of rows (contact.rows.joined); with the
    surface contact, each tool's augmented Lagrange multipliers (ToolState.contact_multipliers_n) updated after each
    step (contact.tool_geometry.update_multipliers); the probes' geometry at the end is left in the tools' arrays
    (as run_frame does).  Returns each tool's contact force on the liver at the end (N: the step's own with one tool
    in contact, else each tool's rows' force at the end state, contact.rows.contact_force_n) and its rows of the
    last step."""
    params = structure.params
    dt = params.dt_s
    gravity = np.asarray(params.gravity_m_s2, dtype=np.float64)
    x, v = state.positions, state.velocities
    surface = params.contact_model == "surface"
    areas = structure.skin_node_area_m2 if surface else None
    if surface:
        for tool_state in state.tools:
            if tool_state.contact_multipliers_n is None or len(tool_state.contact_multipliers_n) != len(x):
                tool_state.contact_multipliers_n = np.zeros(len(x))
    rows = [Contacts.none() for _ in tools]
    liver_force = np.zeros(3)
    for step in range(substeps):
        rows = [Contacts.none() if tool.kind == TOOL_NONE else contact_rows(
            x, v, tool, tool.velocity_m_s * ((step + 1) * dt), dt, areas, params.contact_stiffness_per_area_n_per_m3,
            tool_state.contact_multipliers_n) for tool, tool_state in zip(tools, state.tools)]
        together = joined([r for r in rows if len(r)])
        liver_force = structure.solver.step(state.history, x, v, state.inv_mass, state.external_forces_n, dt,
                                            params.environment_damping_per_s, gravity, together)
        rows = split(together, [len(r) for r in rows])  # as the step left them (surface rows rebuilt at its end)
        if surface:
            for r, tool_state in zip(rows, state.tools):
                update_multipliers(r, x, tool_state.contact_multipliers_n)
    for tool in tools:
        if tool.kind != TOOL_NONE:  # the contact geometry the local model is fitted to
            probe_contacts(x, v, tool, tool.velocity_m_s * (substeps * dt), dt)
    if sum(len(r) > 0 for r in rows) <= 1:  # the step's force is the one tool's in contact, if any
        return [liver_force if len(r) else np.zeros(3) for r in rows], rows
    return [contact_force_n(r, x, v) for r in rows], rows


def spring_forces(structure: Structure, state: State) -> np.ndarray:
    """work.force ← external forces + the springs' Eq. 1 forces + the support at the state (N, 3), returned."""
    f = structure.work.force
    f[:] = state.external_forces_n
    spring_forces_serial(state.positions, state.velocities, structure.spring_arrays, f)
    support = structure.support
    support_forces(state.positions, state.velocities, support.nodes, support.rest_m, support.stiffness_n_per_m,
                   support.damping_ns_per_m, f)
    return f


def divergence(structure: Structure, state: State) -> str | None:
    """None, or the cause when the state is non-finite or a node outruns max_node_speed_m_s."""
    params = structure.params
    speed = max_speed(state.positions, state.velocities)
    if math.isfinite(speed):
        if speed <= params.max_node_speed_m_s:
            return None
        cause = f"node speed {speed:.3g} m/s above max_node_speed_m_s={params.max_node_speed_m_s:g}"
    else:
        cause = "non-finite positions or velocities"
    dt, bound = params.dt_s, structure.stable_dt_s
    if dt > bound:  # never for the implicit integrator (its bound is inf)
        needed = math.ceil(structure.frame_period_s / bound)
        cause += (f"; time step {dt:.3g} s is above the stability bound {bound:.3g} s of "
                  f"{params.integrator} (raise substeps to at least {needed})")
    return f"simulation diverged at t={state.time_s:.4f} s: {cause}; model reset to rest"


def held_pulls(structure: Structure, state: State, holding: Sequence[bool], liver_forces: list[np.ndarray]) -> None:
    """A holding tool's force is the tissue's pull on the nodes it holds (in place in `liver_forces`; the explicit
    kernels leave the last step's forces in the work array)."""
    if not any(holding):
        return
    forces = spring_forces(structure, state) if structure.implicit else structure.work.force
    for k, (tool, holds) in enumerate(zip(state.tools, holding)):
        if holds:
            liver_forces[k] = -forces[tool.held_nodes].sum(axis=0)


def tear_change(structure: Structure, state: State) -> TopologyChange | None:
    """The change that opens the faces stretched beyond the tearing thresholds (physics.topology.tearing), or None;
    a set of faces that opens nothing is kept in the state (State.futile_tear_faces) until it changes."""
    detector = structure.tear_detector
    over = faces_to_tear(detector, state.positions, state.futile_tear_faces)
    if over is None:
        return None
    state.futile_tear_faces = over.copy()
    change = duplication_change(structure.mesh.points, structure.mesh.tets, structure.capsule_triangles,
                                detector.faces[over])
    if change is not None:
        state.futile_tear_faces = None
    return change


def cut_change(structure: Structure, state: State, path_m: np.ndarray, depth_m: float) -> TopologyChange | None:
    """The change that cuts along the blade's path (P, 3) m down to `depth_m` under it (cutting.cut_along_path)."""
    return cut_along_path(structure.mesh.points, structure.mesh.tets, state.positions, structure.capsule_triangles,
                          path_m, depth_m)


def change_topology(structure: Structure, state: State, cause: str,
                    make: Callable[[Structure, State], TopologyChange | None], changes: list, failures: list,
                    failed: str) -> tuple[Structure, State]:
    """The one path of a topology change in a frame: `make` builds it (None: nothing to change) and apply_change
    applies it, all or nothing; `cause` is added to `changes` when the mesh changed, and when anything raises,
    `failed` with the error to `failures` (the structure and state are then as they were and the frame goes on)."""
    try:
        change = make(structure, state)
        if change is not None:
            structure, state = apply_change(structure, state, change)
            changes.append(cause)
    except Exception as exc:
        failures.append(f"{failed}, the mesh is unchanged: {type(exc).__name__}: {exc}")
    return structure, state


def local_models(structure: Structure, state: State, tools: Sequence[Tool], poses: Sequence[ToolPose | None],
                 liver_forces: Sequence[np.ndarray], holding: Sequence[bool],
                 rows: Sequence[Contacts]) -> tuple[LocalModel, ...]:
    """Each tool's local model for the haptic loop (Tool.local_model), the other tools' pushing rows holding the
    tissue under it."""
    pushes = [pushing(r, state.positions, state.velocities) for r in rows] if len(rows) > 1 else []
    return tuple(
        tool.local_model(structure, state, state.tools[k], pose, -force, holds,
                         joined([p for j, p in enumerate(pushes) if j != k and len(p)]) if pushes else None)
        for k, (tool, pose, force, holds) in enumerate(zip(tools, poses, liver_forces, holding)))


def cut_stage(structure: Structure, state: State, tools: Sequence[Tool], models: Sequence[LocalModel],
              changes: list, failures: list) -> tuple[Structure, State]:
    """Each tool's use after a frame with its local model (ToolUse.after_frame): a cutting stroke that ended is cut
    along (change_topology)."""
    for k, (tool, local_model) in enumerate(zip(tools, models)):
        path = tool.use.after_frame(state.tools[k], local_model)
        if path is not None:
            depth_m = tool.use.cut_depth_m
            structure, state = change_topology(structure, state, "cut",
                                               lambda s, x: cut_change(s, x, path, depth_m), changes, failures,
                                               label(tools, k, f"cut along {len(path)} points failed"))
    return structure, state


def warm_up(structure: Structure, state: State, tool: Tool) -> None:
    """Compile the kernels a frame takes (numba, cached on disk): the frame's, and the node duplication of a tear
    or a cut, on a copy of `state` (the state is left as it was)."""
    s = structure
    scratch = replace(state, positions=state.positions.copy(), velocities=state.velocities.copy(),
                      history=s.solver.new_history(), tools=(ToolState(),))
    far = ToolPose(np.full(3, 1e3))
    integrate(s, scratch, [tool.sweep(s, scratch.positions, scratch.tools[0], far)], 0)
    s.solver.warm_up()
    implicit_frame(s, scratch, [tool.sweep(s, scratch.positions, scratch.tools[0], far)], 1)
    spring_forces(s, scratch)
    max_speed(scratch.positions, scratch.velocities)  # the divergence guard's, after every frame
    s.solver.compliance(scratch.positions, scratch.inv_mass, np.ones_like(scratch.positions), 0.0,
                        np.zeros_like(scratch.positions), rotations=scratch.history.rotations)
    s.tear_detector.stretches(state.positions)
    estimate_stable_time_step(s.springs, s.masses_kg, s.params.environment_damping_per_s, s.params.integrator,
                              s.mesh.points, max_iterations=1)
    separate_faces(s.mesh.tets, np.zeros((0, 3), dtype=np.int64))  # opens nothing
