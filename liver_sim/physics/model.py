"""The heterogeneous mass-spring liver (paper §2): state, one frame of simulation, divergence guard.

`LiverModel.step_frame(pose)` advances one frame (1/frame_rate_hz s, `substeps` steps) with the
tool at `pose`, and returns the contact force on the tool and the local model for the haptic loop.
The integrator (params.integrator): linearised backward Euler (physics.implicit, one step per frame
by default), or the explicit kernels (physics.explicit_kernels.run_frame: symplectic Euler, or Eq. 2).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.contact import (
    ToolPose,
    ToolShape,
    force_local_model,
    probe_contacts,
    pull_local_model,
    surface_contacts,
    tool_state,
)
from liver_sim.physics.contact_kernels import TOOL_NONE, ToolState
from liver_sim.physics.cutting import cut_along_path
from liver_sim.physics.explicit_kernels import StepSettings, WorkArrays, max_speed, run_frame
from liver_sim.physics.implicit import ImplicitEuler, StepHistory
from liver_sim.physics.local_stiffness import LocalStiffness
from liver_sim.physics.model_params import ModelParams
from liver_sim.physics.spring_kernels import SpringArrays, spring_forces_serial, support_forces
from liver_sim.physics.springs import build_springs, estimate_stable_time_step, stable_time_step
from liver_sim.physics.support import build_support
from liver_sim.physics.tearing import TearDetector, tear
from liver_sim.physics.topology import NodeState, TopologyChange, carry_over, separate_faces

#: Above this many springs the parallel kernel is used (below it thread start-up costs more).
PARALLEL_MIN_EDGES = 20_000
#: After a topology change the substeps are raised, when needed, to keep dt under this share of the bound.
STABILITY_MARGIN = 0.9


def default_fixed_nodes(mesh: TetMesh) -> np.ndarray:
    """The four nodes of the tet whose centroid is nearest the mesh's volume centroid (paper §3.1)."""
    centroids = mesh.points[mesh.tets].mean(axis=1)
    centre = (centroids * mesh.volumes[:, None]).sum(axis=0) / mesh.volume
    return np.sort(mesh.tets[np.argmin(np.linalg.norm(centroids - centre, axis=1))])


def scaled_masses(masses_kg: np.ndarray, min_fraction: float) -> np.ndarray:
    """Lumped masses raised to at least `min_fraction` × their mean, then rescaled to the same total.

    Mass scaling for the explicit step: the stable time step goes with √m of the lightest nodes,
    which isosurface stuffing makes small at the skin; the organ's mass (paper P2, docs/paper.md) is unchanged.
    """
    floored = np.maximum(masses_kg, min_fraction * masses_kg.mean())
    return floored * (masses_kg.sum() / floored.sum())


@dataclass(frozen=True)
class FrameResult:
    """What one frame produced: simulation time (s), force on the tool (N), local model, divergence,
    and whether the mesh tore at the end of the frame (then `LiverModel.topology_version` moved on), or
    why a tear failed (the mesh is then as it was)."""

    time_s: float
    tool_force_n: np.ndarray
    local_model: LocalModel
    divergence: str | None
    topology_changed: bool = False
    topology_failure: str | None = None


class LiverModel:
    """A liver mesh, its springs and masses, and its state (positions in m, velocities in m/s).

    `external_forces_n` (N, 3) are applied to the nodes at every step (zero by default).
    `capsule_triangles` are the skin triangles carrying capsule springs (the whole skin until a tear
    or a cut opens faces); `apply_topology` replaces the mesh and increments `topology_version`,
    `apply_topology_change` does so all or nothing (how tears and cuts are applied).
    `held_nodes` (see `hold`) are moved by the tool, like the fixed nodes by the scene, not integrated.
    `local_stiffness` (physics.local_stiffness) gives the local model's K under the tool.
    `support` (physics.support) ties the supported capsule nodes to their rest positions; with
    `params.support` 'organ' and `fixed_nodes` None, no node is fixed unless the support regions hold
    no capsule node of the mesh (then the paper's central tet is, as with 'paper').
    """

    def __init__(self, mesh: TetMesh, params: ModelParams | None = None, tool: ToolShape | None = None,
                 local_model: str = "plane", local_model_reach_m: float = 0.02, parallel: bool | None = None):
        self.params = (params or ModelParams()).validate()
        self.tool = tool or ToolShape()
        if local_model not in ("plane", "sphere"):
            raise ValueError(f"parameter local_model must be 'plane' or 'sphere', got {local_model!r}")
        self.local_model_kind = local_model
        self.local_model_reach_m = float(local_model_reach_m)
        masses = scaled_masses(mesh.lumped_masses(self.params.density_kg_m3), self.params.min_node_mass_fraction)
        fixed = self.params.fixed_nodes
        if fixed is None:  # the paper's scene, unless the organ's support holds the liver
            held = len(build_support(mesh, mesh.skin, self.params).nodes) > 0
            fixed = np.zeros(0, np.int64) if held else default_fixed_nodes(mesh)
        fixed = np.unique(np.asarray(fixed, np.int64))
        if fixed.size and (fixed.min() < 0 or fixed.max() >= len(mesh.points)):
            raise ValueError(f"parameter fixed_nodes must index nodes 0..{len(mesh.points) - 1}")
        self.held_nodes = np.zeros(0, dtype=np.int64)
        self.parallel = None if parallel is None else bool(parallel)
        self._set_mesh(mesh, mesh.skin, NodeState(mesh.points.copy(), np.zeros_like(mesh.points),
                                                  np.zeros_like(mesh.points), masses, fixed))
        self.stable_dt_s = math.inf if self.implicit else stable_time_step(
            self.springs, self.masses_kg, self.params.environment_damping_per_s, self.params.integrator, mesh.points,
            self.support)
        self._tear_detector: tuple[tuple, TearDetector] | None = None
        self.topology_version = 0
        self.divergences = 0
        self.time_s = 0.0
        self.reset()

    def _set_mesh(self, mesh: TetMesh, capsule_triangles: np.ndarray, state: NodeState) -> None:
        """Take `mesh`, its capsule, springs and node state, and the kernels' arrays for them."""
        self.mesh = mesh
        self.capsule_triangles = np.ascontiguousarray(capsule_triangles, dtype=np.int64).reshape(-1, 3)
        self.positions, self.velocities, self.external_forces_n, self.masses_kg, self.fixed_nodes = state
        self.springs = springs = build_springs(mesh, self.params, capsule_triangles=self.capsule_triangles)
        self.support = build_support(mesh, self.capsule_triangles, self.params)
        self._spring_arrays = SpringArrays(springs.node_i, springs.node_j, springs.rest_length_m,
                                           springs.lambda1_n, springs.lambda2_n, springs.mu_ns_per_m)
        if self.parallel is None:  # chosen once, for the first mesh
            self.parallel = springs.edges >= PARALLEL_MIN_EDGES
        threads = numba.get_num_threads() if self.parallel else 1
        self._work = WorkArrays(np.zeros_like(mesh.points), np.zeros((threads, len(mesh.points), 3)), self.parallel)
        self._skin = np.ascontiguousarray(mesh.skin, dtype=np.int64)
        self._solver = ImplicitEuler(springs, len(mesh.points), support=self.support)
        self._step_history = StepHistory(len(mesh.points))
        self.local_stiffness = LocalStiffness(self._solver, len(mesh.points))
        self.hold(self.held_nodes)

    @property
    def implicit(self) -> bool:
        """True when the integrator is linearised backward Euler (no stability bound on the step)."""
        return self.params.integrator == "implicit_euler"

    def apply_topology(self, change: TopologyChange) -> None:
        """Replace the mesh by `change`'s (a tear or a cut), carrying state, masses and forces over
        (topology.carry_over); with an explicit integrator, raise the substeps if the new springs and
        masses need it (the implicit one keeps its steps)."""
        state = NodeState(self.positions, self.velocities, self.external_forces_n, self.masses_kg, self.fixed_nodes)
        mesh, state = carry_over(change, state, self.mesh.source, self.params.density_kg_m3,
                                 self.params.min_node_mass_fraction)
        self._set_mesh(mesh, change.capsule_triangles, state)
        params = self.params
        self.stable_dt_s = math.inf if self.implicit else estimate_stable_time_step(
            self.springs, self.masses_kg, params.environment_damping_per_s, params.integrator, mesh.points,
            support=self.support)
        if self.params.dt_s > STABILITY_MARGIN * self.stable_dt_s:  # new short springs or light nodes
            needed = math.ceil(self.frame_period_s / (STABILITY_MARGIN * self.stable_dt_s))
            self.params = self.params.with_changes(substeps=min(needed, 10_000))
        self.topology_version += 1  # the tear detector is keyed by it

    def apply_topology_change(self, change: TopologyChange) -> None:
        """`apply_topology(change)` all or nothing: the change is checked (carry_over: check_change) before
        the model is touched; if applying raises midway, every attribute of the model is put back, with the
        contents of its arrays, and the error re-raised: positions, velocities, masses, mesh, springs, fixed
        and held nodes, topology_version are then as they were."""
        saved = dict(vars(self))
        contents = {name: value.copy() for name, value in saved.items() if isinstance(value, np.ndarray)}
        try:
            self.apply_topology(change)
        except BaseException:
            for name, value in contents.items():
                if saved[name].flags.writeable:
                    np.copyto(saved[name], value)
            vars(self).clear()
            vars(self).update(saved)
            raise

    def cut(self, path_m: np.ndarray, depth_m: float) -> bool:
        """Cut along the blade's path (P, 3) m, deformed frame, down to `depth_m` under it (P14, §3.5;
        see cutting.cut_along_path); True when the mesh changed.  All or nothing (apply_topology_change):
        when it raises, the model is as it was."""
        change = cut_along_path(self.mesh.points, self.mesh.tets, self.positions, self.capsule_triangles,
                                path_m, depth_m)
        if change is not None:
            self.apply_topology_change(change)
        return change is not None

    def hold(self, nodes: np.ndarray) -> None:
        """Let the tool move `nodes` (step_frame's held_positions) instead of the integrator; none: let go."""
        self.held_nodes = np.asarray(nodes, dtype=np.int64)
        self.inv_mass = 1.0 / self.masses_kg
        self.inv_mass[self.fixed_nodes] = 0.0
        self.inv_mass[self.held_nodes] = 0.0

    def reset(self) -> None:
        """Back to the rest shape, at rest, with no tool history and nothing held; the clock runs on."""
        self.positions = self.mesh.points.copy()
        self.velocities = np.zeros_like(self.positions)
        self._previous_pose: ToolPose | None = None
        self._step_history.reset()
        self.local_stiffness.reset()
        if self.held_nodes.size:
            self.hold(np.zeros(0, dtype=np.int64))

    def warm_up(self) -> None:
        """Compile the kernels (numba, cached on disk) before a timed loop starts: the frame's, and the node
        duplication of a tear or a cut (a first tear in the loop would otherwise stall it while it compiles)."""
        self._advance(ToolPose(np.full(3, 1e3)), substeps=0)
        self._solver.warm_up()
        state = self.positions.copy(), self.velocities.copy()
        self._implicit_frame(self._tool_state(ToolPose(np.full(3, 1e3))), 1)
        self._spring_forces()
        max_speed(self.positions, self.velocities)  # the divergence guard's, after every frame
        self._solver.compliance(self.positions, self.inv_mass, np.ones_like(self.positions), 0.0,
                                np.zeros_like(self.positions))
        self.positions[:], self.velocities[:] = state
        self._step_history.reset()
        self._previous_pose = None
        self._detector().stretches(self.positions)
        estimate_stable_time_step(self.springs, self.masses_kg, self.params.environment_damping_per_s,
                                  self.params.integrator, self.mesh.points, max_iterations=1)
        separate_faces(self.mesh.tets, np.zeros((0, 3), dtype=np.int64))  # opens nothing

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.params.frame_rate_hz

    def displacement_m(self) -> np.ndarray:
        """|x − x_rest| per node (m)."""
        return np.linalg.norm(self.positions - self.mesh.points, axis=1)

    def step_frame(self, pose: ToolPose | None = None, held_positions: np.ndarray | None = None) -> FrameResult:
        """Advance one frame with the tool at `pose` (None: no tool). Resets and reports on divergence.

        With `held_positions` (one per held node, m) the tool holds those nodes there instead of pushing
        (no contact), moving at the speed that takes them there in one frame: the force on the tool is
        the tissue's pull on them, and the local model contact.pull_local_model's.  With
        `params.tearing`, faces stretched beyond their threshold then open (`tear`).
        """
        holding = pose is not None and held_positions is not None
        if holding:
            self.velocities[self.held_nodes] = (held_positions - self.positions[self.held_nodes]) / self.frame_period_s
            self.positions[self.held_nodes] = held_positions
        liver_force, tool = self._advance(None if holding else pose, self.params.substeps)
        if holding:
            if self.implicit:  # the explicit kernels leave the last step's forces in the work array
                self._spring_forces()
            liver_force = -self._work.force[self.held_nodes].sum(axis=0)
        self.time_s += self.frame_period_s
        divergence = self._check_divergence()
        if divergence is not None:
            self.divergences += 1
            self.reset()
            return FrameResult(self.time_s, np.zeros(3), LocalModel.invalid(), divergence)
        torn, failure = self._tear() if self.params.tearing else (False, None)
        if pose is None:
            local_model = LocalModel.invalid()
        elif holding:
            local_model = pull_local_model(pose, -liver_force, self.params.contact_stiffness_n_per_m,
                                           self.tool.radius_m)
        else:
            local_model = force_local_model(self.tool, pose, tool, -liver_force, self._stiffness_under(tool),
                                            self.local_model_reach_m, self.local_model_kind, self.positions)
        return FrameResult(self.time_s, -liver_force, local_model, None, torn, failure)

    def _stiffness_under(self, tool: ToolState) -> float:
        """K of the local model under the tool (physics.local_stiffness)."""
        return self.local_stiffness.stiffness_n_per_m(tool, self.positions, self.inv_mass,
                                                      self.params.contact_stiffness_n_per_m,
                                                      self.params.environment_damping_per_s)

    def _detector(self) -> TearDetector:
        """The TearDetector of the current mesh and thresholds (rebuilt when either changes)."""
        key = (self.topology_version, self.params.tear_strain_parenchyma, self.params.tear_strain_capsule)
        if self._tear_detector is None or self._tear_detector[0] != key:
            self._tear_detector = (key, TearDetector(self.mesh.points, self.mesh.tets, self.capsule_triangles,
                                                     key[1], key[2]))
        return self._tear_detector[1]

    def _tear(self) -> tuple[bool, str | None]:
        """Open the faces stretched beyond the tearing thresholds, all or nothing (apply_topology_change):
        (True when the mesh changed, why the tear failed or None)."""
        params = self.params
        try:
            change = tear(self.mesh.points, self.mesh.tets, self.positions, self.capsule_triangles,
                          params.tear_strain_parenchyma, params.tear_strain_capsule, detector=self._detector())
            if change is not None:
                self.apply_topology_change(change)
        except Exception as exc:  # the model is as it was; the frame goes on
            return False, f"tear failed, the mesh is unchanged: {type(exc).__name__}: {exc}"
        return change is not None, None

    def _advance(self, pose: ToolPose | None, substeps: int) -> tuple[np.ndarray, ToolState]:
        """Run `substeps` steps with the tool moving from the previous pose to `pose` (contact.tool_state).
        Returns the contact force on the liver (N) and the tool's state (its candidates' contact geometry)."""
        params = self.params
        tool = self._tool_state(pose)
        self._previous_pose = pose
        if self.implicit:
            return self._implicit_frame(tool, substeps), tool
        settings = StepSettings(params.dt_s, substeps, params.environment_damping_per_s,
                                np.asarray(params.gravity_m_s2, dtype=np.float64),
                                params.integrator == "symplectic_euler")
        liver_force = run_frame(self.positions, self.velocities, self.inv_mass, self.external_forces_n,
                                self._spring_arrays, self.support, settings, tool, self._work)
        return liver_force, tool

    def _tool_state(self, pose: ToolPose | None) -> ToolState:
        return tool_state(self.tool, pose, self._previous_pose, self.params, self.local_model_reach_m,
                          self.positions, self._skin)

    def _implicit_frame(self, tool: ToolState, substeps: int) -> np.ndarray:
        """`substeps` backward-Euler steps with the tool's contacts with the skin triangles taken where its
        probes are at the end of each step (contact.surface_contacts); the probes' geometry at the end is
        left in the tool's arrays (as run_frame does).  Returns the contact force on the liver at the end (N)."""
        params = self.params
        dt = params.dt_s
        gravity = np.asarray(params.gravity_m_s2, dtype=np.float64)
        x, v = self.positions, self.velocities
        liver_force = np.zeros(3)
        for step in range(substeps):
            contacts = None if tool.kind == TOOL_NONE else surface_contacts(
                x, v, tool, tool.velocity_m_s * ((step + 1) * dt), dt)
            liver_force = self._solver.step(self._step_history, x, v, self.inv_mass, self.external_forces_n, dt,
                                            params.environment_damping_per_s, gravity, contacts)
        if tool.kind != TOOL_NONE:  # the contact geometry the local model is fitted to
            probe_contacts(x, v, tool, tool.velocity_m_s * (substeps * dt), dt)
        return liver_force

    def _spring_forces(self) -> None:
        """work.force ← external forces + the springs' Eq. 1 forces + the support at the current state."""
        f = self._work.force
        f[:] = self.external_forces_n
        s = self._spring_arrays
        spring_forces_serial(self.positions, self.velocities, s.node_i, s.node_j, s.rest_m, s.lambda1_n, s.lambda2_n,
                             s.mu_ns_per_m, f)
        support = self.support
        support_forces(self.positions, self.velocities, support.nodes, support.rest_m, support.stiffness_n_per_m,
                       support.damping_ns_per_m, f)

    def _check_divergence(self) -> str | None:
        """None, or the cause when the state is non-finite or a node outruns max_node_speed_m_s."""
        speed = max_speed(self.positions, self.velocities)
        if math.isfinite(speed):
            if speed <= self.params.max_node_speed_m_s:
                return None
            cause = f"node speed {speed:.3g} m/s above max_node_speed_m_s={self.params.max_node_speed_m_s:g}"
        else:
            cause = "non-finite positions or velocities"
        dt = self.params.dt_s
        if dt > self.stable_dt_s:  # never for the implicit integrator (stable_dt_s is inf)
            needed = math.ceil(self.frame_period_s / self.stable_dt_s)
            cause += (f"; time step {dt:.3g} s is above the stability bound {self.stable_dt_s:.3g} s of "
                      f"{self.params.integrator} (raise substeps to at least {needed})")
        return f"simulation diverged at t={self.time_s:.4f} s: {cause}; model reset to rest"
