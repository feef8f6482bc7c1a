"""The heterogeneous mass-spring liver (paper §2): a Structure, its State, its tools, and the frame that steps them.

`LiverModel.step_frame(*poses)` advances one frame (1/frame_rate_hz s, `substeps` steps) with each tool at its
pose, in one place: the tools' use before the frame (grasp or let go) → the tools over the frame (their probes and
candidate triangles) → the integration with their contacts (linearised backward Euler, physics.solver.implicit, one step
per frame by default, every tool's contact rows in the same step (physics.contact.rows); or, for one tool, the
explicit kernels, physics.solver.explicit_kernels.run_frame: symplectic Euler, or Eq. 2) → the divergence guard → a tear
→ each tool's local model for the haptic loop → a cut at the end of a stroke.  Tears and cuts take one path
(`apply`): the new structure and state are built beside the old ones and replace them only when both are whole.

Two tools meet only through the tissue: neither collides with the other (they pass through each other), a node
held by one is not grasped by another, and a tool pressing a node another holds feels that node where the holding
tool puts it (the holding tool feels the tissue's pull on the node, not that press).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from liver_sim.base import kernel_cache
from liver_sim.base.local_model import LocalModel
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.contact.kernels import TOOL_NONE, ToolSweep
from liver_sim.physics.contact.rows import Contacts, contact_force_n, joined, pushing
from liver_sim.physics.contact.tool_geometry import ToolPose, contact_rows, probe_contacts
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver.explicit_kernels import max_speed, run_frame
from liver_sim.physics.state import State, carried_state, rest_state
from liver_sim.physics.structure import Structure, build_structure, initial_structure
from liver_sim.physics.tissue.spring_kernels import spring_forces_serial, support_forces
from liver_sim.physics.tissue.springs import estimate_stable_time_step
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.topology.change import NodeState, TopologyChange, carry_over, separate_faces
from liver_sim.physics.topology.cutting import cut_along_path
from liver_sim.physics.topology.tearing import tear


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
    """`substeps` backward-Euler steps, each with every tool's contacts with the skin triangles, taken where its
    probes are at the end of the step (contact.tool_geometry.contact_rows), in one set of rows (contact.rows.joined);
    the probes' geometry at the end is left in the tools' arrays (as run_frame does).  Returns each tool's contact
    force on the liver at the end (N: the step's own with one tool in contact, else each tool's rows' force at
    the end state, contact.rows.contact_force_n) and its rows of the last step."""
    params = structure.params
    dt = params.dt_s
    gravity = np.asarray(params.gravity_m_s2, dtype=np.float64)
    x, v = state.positions, state.velocities
    areas = structure.skin_node_area_m2 if params.contact_model == "surface" else None
    rows = [Contacts.none() for _ in tools]
    liver_force = np.zeros(3)
    for step in range(substeps):
        rows = [Contacts.none() if tool.kind == TOOL_NONE else contact_rows(
            x, v, tool, tool.velocity_m_s * ((step + 1) * dt), dt, areas, params.contact_stiffness_per_area_n_per_m3)
            for tool in tools]
        touching = [r for r in rows if len(r)]
        liver_force = structure.solver.step(state.history, x, v, state.inv_mass, state.external_forces_n, dt,
                                            params.environment_damping_per_s, gravity,
                                            joined(touching))
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
    s = structure.spring_arrays
    spring_forces_serial(state.positions, state.velocities, s.node_i, s.node_j, s.rest_m, s.lambda1_n, s.lambda2_n,
                         s.mu_ns_per_m, f)
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


class LiverModel:
    """A liver: its `structure` (replaced whole by a tear or a cut), its `state` and its `tools` (ToolContacts, one
    by default; `tool` is the first); `divergences` counts the frames that diverged (the model was then reset to
    rest).  More than one tool needs the implicit integrator (the explicit kernels step one tool's contact).

    `state.external_forces_n` (N, 3) are applied to the nodes at every step (zero by default).
    `state.held_nodes` (every tool's, see `grasp`) are moved by the tools, like the fixed nodes by the scene, not
    integrated.  With `params.support` 'organ' and `fixed_nodes` None, no node is fixed unless the support regions
    hold no capsule node of the mesh (then the paper's central tet is, as with 'paper'):
    structure.initial_structure.
    """

    def __init__(self, mesh: TetMesh, params: ModelParams | None = None,
                 tool: Tool | Sequence[Tool] | None = None):
        self.structure = initial_structure(mesh, params)
        self.state = rest_state(self.structure)
        self.tools = (tool,) if isinstance(tool, Tool) else tuple(tool) if tool is not None else (Tool(),)
        names = [t.name for t in self.tools]
        if not self.tools or len(set(names)) != len(names):
            raise ValueError(f"parameter tools must name one tool or more, each once, got {names}")
        if len(self.tools) > 1 and not self.structure.implicit:
            raise ValueError(f"parameter integrator={self.structure.params.integrator!r}: {len(self.tools)} tools "
                             "need implicit_euler (an explicit integrator steps one tool's contact)")
        self.divergences = 0

    @property
    def tool(self) -> Tool:
        """The first tool (the only one by default)."""
        return self.tools[0]

    def step_frame(self, *poses: ToolPose | None) -> FrameResult:
        """Advance one frame with each tool at its pose, in the order of `tools` (None: that tool is away; no pose
        at all: every tool is); resets to rest on divergence (module doc).

        Holding nodes (grasp), a tool moves them to where it holds them, at the speed that takes them there in
        one frame, instead of pushing: its force is the tissue's pull on them and its local model
        contact.tool_geometry.pull_local_model's.  With `params.tearing`, faces stretched beyond their
        threshold then open.
        """
        poses = self._poses(poses)
        events = self.before_frame(*poses)
        s, state = self.structure, self.state
        holding = [pose is not None and tool.use.holding for tool, pose in zip(self.tools, poses)]
        for tool, pose, holds in zip(self.tools, poses, holding):
            if holds:
                nodes, held = tool.use.held_nodes, tool.use.held_positions(pose)
                state.velocities[nodes] = (held - state.positions[nodes]) / s.frame_period_s
                state.positions[nodes] = held
        contacts = [tool.over_frame(s, state, None if holds else pose)
                    for tool, pose, holds in zip(self.tools, poses, holding)]
        liver_forces, rows = integrate(s, state, contacts, s.params.substeps)
        if any(holding):  # the explicit kernels leave the last step's forces in the work array
            forces = spring_forces(s, state) if s.implicit else s.work.force
            for k, (tool, holds) in enumerate(zip(self.tools, holding)):
                if holds:
                    liver_forces[k] = -forces[tool.use.held_nodes].sum(axis=0)
        state.time_s += s.frame_period_s
        diverged = divergence(s, state)
        if diverged is not None:
            self.divergences += 1
            self.reset()
            invalid = tuple(LocalModel.invalid() for _ in self.tools)
            changes, failures = self.after_frame(*invalid)
            return FrameResult(state.time_s, tuple(np.zeros(3) for _ in self.tools), invalid, diverged,
                               tuple(changes), tuple(failures), events)
        changes, failures = [], []
        if s.params.tearing:
            self._change("torn", self._tear, changes, failures, "tear failed")
        pushes = [pushing(r, self.state.positions, self.state.velocities) for r in rows] if len(rows) > 1 else []
        local_models = tuple(
            tool.local_model(self.structure, self.state, pose, -force, holds,
                             joined([p for j, p in enumerate(pushes) if j != k and len(p)]) if pushes else None)
            for k, (tool, pose, force, holds) in enumerate(zip(self.tools, poses, liver_forces, holding)))
        more_changes, more_failures = self.after_frame(*local_models)
        return FrameResult(self.state.time_s, tuple(-force for force in liver_forces), local_models, None,
                           tuple(changes + more_changes), tuple(failures + more_failures), events)

    def _poses(self, poses: tuple) -> tuple:
        """One pose (or None) per tool: `poses` as given, or every tool away when none is given."""
        if not poses:
            return (None,) * len(self.tools)
        if len(poses) != len(self.tools):
            raise ValueError(f"step_frame takes one pose per tool: {len(self.tools)}, got {len(poses)}")
        return poses

    def _label(self, k: int, text: str) -> str:
        """`text` of tool k, after its name when it has one."""
        name = self.tools[k].name
        return f"{name}: {text}" if name else text

    def before_frame(self, *poses: ToolPose | None) -> tuple[str, ...]:
        """Each tool's use before a frame (ToolUse.before_frame): grasp what it touches, or let go; what they did."""
        events = []
        for k, (tool, pose) in enumerate(zip(self.tools, self._poses(poses))):
            decision = tool.use.before_frame(pose)
            if decision == "grasp":
                events.append(self._label(k, f"grasped {self.grasp(pose, k)} skin node(s)"))
            elif decision == "release":
                self.release(k)
                events.append(self._label(k, "released the grasped nodes"))
        return tuple(events)

    def after_frame(self, *local_models: LocalModel) -> tuple[list[str], list[str]]:
        """Each tool's use after a frame with its local model (in the order of `tools`): a cutting stroke that ended
        is cut along (`cut`); (['cut', …] or [], why each failed or [])."""
        changes, failures = [], []
        for k, (tool, local_model) in enumerate(zip(self.tools, local_models)):
            path = tool.use.after_frame(local_model)
            if path is not None:
                depth_m = tool.use.cut_depth_m
                self._change("cut", lambda: self._cut_change(path, depth_m), changes, failures,
                             self._label(k, f"cut along {len(path)} points failed"))
        return changes, failures

    def grasp(self, pose: ToolPose, tool: int = 0) -> int:
        """Let tool `tool` hold the skin nodes it touches at `pose` (ToolUse.grasp; none another tool holds), from
        the next frame on moved with it, kinematically, until `release()`; returns how many."""
        use = self.tools[tool].use
        others = [t.use.held_nodes for j, t in enumerate(self.tools) if j != tool and t.use.holding]
        skin_nodes = self.structure.mesh.skin_nodes
        free = np.setdiff1d(skin_nodes, np.concatenate(others)) if others else skin_nodes
        nodes = use.grasp(self.tools[tool].shape, pose, self.state.positions, free)
        self._hold()
        return len(nodes)

    def release(self, tool: int | None = None) -> None:
        """Let go of the nodes tool `tool` holds (None: every tool's)."""
        for k, t in enumerate(self.tools):
            if tool is None or k == tool:
                t.use.release()
        self._hold()

    def _hold(self) -> None:
        """The state holds what the tools hold."""
        held = [t.use.held_nodes for t in self.tools]
        self.state.hold(self.structure, held[0] if len(held) == 1 else np.concatenate(held))

    def cut(self, path_m: np.ndarray, depth_m: float) -> bool:
        """Cut along the blade's path (P, 3) m, deformed frame, down to `depth_m` under it (P14, §3.5; see
        cutting.cut_along_path); True when the mesh changed.  All or nothing (`apply`)."""
        change = self._cut_change(path_m, depth_m)
        if change is not None:
            self.apply(change)
        return change is not None

    def apply(self, change: TopologyChange) -> None:
        """Replace the structure and the state by those after `change` (apply_change); when that raises, the
        model is as it was."""
        self.structure, self.state = apply_change(self.structure, self.state, change)

    def reset(self) -> None:
        """Back to the rest shape, at rest, with no tool history and nothing held; the clock runs on."""
        self.state.rest(self.structure)
        for tool in self.tools:
            tool.forget()

    def warm_up(self) -> None:
        """Compile the kernels (numba, cached on disk) before a timed loop starts: the frame's, and the node
        duplication of a tear or a cut (a first tear in the loop would otherwise stall it while it compiles); under the
        cache's lock (base.kernel_cache.compiling), so that processes warming up at once do not corrupt it."""
        with kernel_cache.compiling():
            self._warm_up()

    def _warm_up(self) -> None:
        s, state = self.structure, self.state
        far = ToolPose(np.full(3, 1e3))
        integrate(s, state, [self.tool.over_frame(s, state, far)], 0)
        s.solver.warm_up()
        saved = state.positions.copy(), state.velocities.copy()
        implicit_frame(s, state, [self.tool.over_frame(s, state, far)], 1)
        spring_forces(s, state)
        max_speed(state.positions, state.velocities)  # the divergence guard's, after every frame
        s.solver.compliance(state.positions, state.inv_mass, np.ones_like(state.positions), 0.0,
                            np.zeros_like(state.positions))
        state.positions[:], state.velocities[:] = saved
        state.history.reset()
        for tool in self.tools:
            tool.previous_pose = None
        s.tear_detector.stretches(state.positions)
        estimate_stable_time_step(s.springs, s.masses_kg, s.params.environment_damping_per_s, s.params.integrator,
                                  s.mesh.points, max_iterations=1)
        separate_faces(s.mesh.tets, np.zeros((0, 3), dtype=np.int64))  # opens nothing

    def _tear(self) -> TopologyChange | None:
        """The change that opens the faces stretched beyond the tearing thresholds (tearing.tear), or None."""
        s, p = self.structure, self.structure.params
        return tear(s.mesh.points, s.mesh.tets, self.state.positions, s.capsule_triangles, p.tear_strain_parenchyma,
                    p.tear_strain_capsule, detector=s.tear_detector)

    def _cut_change(self, path_m: np.ndarray, depth_m: float) -> TopologyChange | None:
        s = self.structure
        return cut_along_path(s.mesh.points, s.mesh.tets, self.state.positions, s.capsule_triangles, path_m, depth_m)

    def _change(self, cause: str, make, changes: list, failures: list, failed: str) -> None:
        """The one path of a topology change in a frame: `make()` builds it (None: nothing to change) and `apply`
        applies it, all or nothing; `cause` is added to `changes` when the mesh changed, and when anything raises,
        `failed` with the error to `failures` (the model is then as it was and the frame goes on)."""
        try:
            change = make()
            if change is not None:
                self.apply(change)
                changes.append(cause)
        except Exception as exc:
            failures.append(f"{failed}, the mesh is unchanged: {type(exc).__name__}: {exc}")
