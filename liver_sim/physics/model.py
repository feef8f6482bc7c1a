"""The heterogeneous mass-spring liver (paper §2): state, one frame of simulation, divergence guard.

`LiverModel.step_frame(pose)` advances one frame (1/frame_rate_hz s, `substeps` steps) with the
tool at `pose`, and returns the contact force on the tool and the local model for the haptic loop.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics import kernels
from liver_sim.physics.contact import (TOOL_KINDS, LocalModel, ToolPose, ToolShape, candidate_nodes,
                                       candidate_triangles, fit_local_model, tool_core)
from liver_sim.physics.params import ModelParams
from liver_sim.physics.springs import build_springs, estimate_stable_time_step, stable_time_step
from liver_sim.physics.cutting import cut_along_path
from liver_sim.physics.topology import TearDetector, TopologyChange, tear

#: A tool that moves farther than this in one frame is taken as re-placed, not as moving (m).
TOOL_JUMP_M = 0.05
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
    which isosurface stuffing makes small at the skin; the organ's mass (P2) is unchanged.
    """
    floored = np.maximum(masses_kg, min_fraction * masses_kg.mean())
    return floored * (masses_kg.sum() / floored.sum())


@dataclass(frozen=True)
class FrameResult:
    """What one frame produced: simulation time (s), force on the tool (N), local model, divergence,
    and whether the mesh tore at the end of the frame (then `LiverModel.topology_version` moved on)."""

    time_s: float
    tool_force_n: np.ndarray
    local_model: LocalModel
    divergence: str | None
    topology_changed: bool = False


class LiverModel:
    """A liver mesh, its springs and masses, and its state (positions in m, velocities in m/s).

    `external_forces_n` (N, 3) are applied to the nodes at every step (zero by default).
    `capsule_triangles` are the skin triangles carrying capsule springs (the whole skin until a tear
    or a cut opens faces); `apply_topology` replaces the mesh and increments `topology_version`.
    """

    def __init__(self, mesh: TetMesh, params: ModelParams | None = None, tool: ToolShape | None = None,
                 local_model: str = "plane", local_model_reach_m: float = 0.02, parallel: bool | None = None):
        self.mesh = mesh
        self.params = (params or ModelParams()).validate()
        self.tool = tool or ToolShape()
        if local_model not in ("plane", "sphere"):
            raise ValueError(f"parameter local_model must be 'plane' or 'sphere', got {local_model!r}")
        self.local_model_kind = local_model
        self.local_model_reach_m = float(local_model_reach_m)
        self.capsule_triangles = np.ascontiguousarray(mesh.skin)
        self.springs = build_springs(mesh, self.params, capsule_triangles=self.capsule_triangles)
        self.masses_kg = scaled_masses(mesh.lumped_masses(self.params.density_kg_m3),
                                       self.params.min_node_mass_fraction)
        fixed = self.params.fixed_nodes
        self.fixed_nodes = default_fixed_nodes(mesh) if fixed is None else np.unique(np.asarray(fixed, np.int64))
        if self.fixed_nodes.size and (self.fixed_nodes.min() < 0 or self.fixed_nodes.max() >= len(mesh.points)):
            raise ValueError(f"parameter fixed_nodes must index nodes 0..{len(mesh.points) - 1}")
        self.grasped_nodes = np.zeros(0, dtype=np.int64)
        self._refresh_inverse_masses()
        self.stable_dt_s = stable_time_step(self.springs, self.masses_kg, self.params.environment_damping_per_s,
                                            self.params.integrator, mesh.points)
        self.parallel = self.springs.edges >= PARALLEL_MIN_EDGES if parallel is None else bool(parallel)
        self._set_mesh_arrays()
        self.external_forces_n = np.zeros_like(mesh.points)
        self._gravity = np.asarray(self.params.gravity_m_s2, dtype=np.float64)
        self._tear_detector: tuple[tuple, TearDetector] | None = None
        self.topology_version = 0
        self.divergences = 0
        self.time_s = 0.0
        self.reset()

    def _set_mesh_arrays(self) -> None:
        """Skin, skin nodes, centre and work arrays of the current mesh (contact and kernels)."""
        mesh = self.mesh
        self._skin = np.ascontiguousarray(mesh.skin)
        self._skin_nodes = mesh.skin_nodes
        self._centre = mesh.points.mean(axis=0)
        self._force = np.zeros_like(mesh.points)
        self._partial_forces = np.zeros((numba.get_num_threads() if self.parallel else 1, len(mesh.points), 3))

    def apply_topology(self, change: TopologyChange) -> None:
        """Replace the mesh by `change`'s (a tear or a cut), carrying state, masses and forces over.

        New positions, velocities: x'_k = Σ w·x[source].  Masses: old node i's mass goes to the new
        nodes that draw on it, in shares ∝ w·(their lumped tet mass); each share is first raised to
        φ_i = min(min_node_mass_fraction·mean mass / m_i, 1/n_i) (n_i: nodes drawing on i) and the
        shares renormalised, so a copy keeps at least φ_i/2 of m_i.  Each old mass is so split
        exactly: the total is conserved and, for duplicated nodes (one source, weight 1), so is the
        momentum; mass of an old node nothing draws on is spread over all nodes ∝ mass.  External
        forces are split with the same shares.  A new node drawing only on fixed nodes is fixed.
        """
        sources = np.asarray(change.node_sources, dtype=np.int64)
        weights = np.asarray(change.node_weights, dtype=np.float64)
        old_count = len(self.positions)
        if sources.ndim != 2 or sources.shape != weights.shape or len(sources) != len(change.rest_points):
            raise ValueError("topology change: node_sources and node_weights must both be (N', S) "
                             f"with N' = {len(change.rest_points)} rest points")
        if sources.size and (sources.min() < 0 or sources.max() >= old_count):
            raise ValueError(f"topology change: node_sources must index the old nodes 0..{old_count - 1}")
        mesh = TetMesh.from_arrays(change.rest_points, change.tets, source=self.mesh.source)
        if len(mesh.points) != len(change.rest_points) or not np.array_equal(mesh.tets, change.tets):
            raise ValueError("topology change: tets must use every node and be positively oriented at rest")
        used = weights > 0.0
        claims = np.where(used, weights, 0.0) * mesh.lumped_masses(self.params.density_kg_m3)[:, None]
        share = self._mass_shares(sources, claims, used, old_count)
        masses = (share * self.masses_kg[sources]).sum(axis=1)
        masses *= self.masses_kg.sum() / masses.sum()
        fixed_old = np.zeros(old_count, dtype=bool)
        fixed_old[self.fixed_nodes] = True
        fixed = used.any(axis=1) & (fixed_old[sources] | ~used).all(axis=1)
        self.positions = np.einsum("ks,ksj->kj", weights, self.positions[sources])
        self.velocities = np.einsum("ks,ksj->kj", weights, self.velocities[sources])
        self.external_forces_n = np.einsum("ks,ksj->kj", share, self.external_forces_n[sources])
        self.mesh = mesh
        self.capsule_triangles = np.ascontiguousarray(change.capsule_triangles, dtype=np.int64).reshape(-1, 3)
        self.springs = build_springs(mesh, self.params, capsule_triangles=self.capsule_triangles)
        self.masses_kg = masses
        self.fixed_nodes = np.flatnonzero(fixed)
        self._refresh_inverse_masses()
        self._set_mesh_arrays()
        self.stable_dt_s = estimate_stable_time_step(self.springs, masses, self.params.environment_damping_per_s,
                                                     self.params.integrator, mesh.points)
        if self.params.dt_s > STABILITY_MARGIN * self.stable_dt_s:  # new short springs or light nodes
            needed = math.ceil(self.frame_period_s / (STABILITY_MARGIN * self.stable_dt_s))
            self.params = self.params.with_changes(substeps=min(needed, 10_000))
        self.topology_version += 1  # the tear detector is keyed by it

    def cut(self, path_m: np.ndarray, depth_m: float) -> bool:
        """Cut along the blade's path (P, 3) m, deformed frame, down to `depth_m` under it (P14, §3.5;
        see cutting.cut_along_path); True when the mesh changed."""
        change = cut_along_path(self.mesh.points, self.mesh.tets, self.positions, self.capsule_triangles,
                                path_m, depth_m)
        if change is None:
            return False
        self.apply_topology(change)
        return True

    def grasp(self, pose: ToolPose, margin_m: float) -> int:
        """Hold the skin nodes within the tool's bounding ball (+ `margin_m`) where they are in the tool
        frame: from the next frame on they move with the tool, kinematically, until `release()`.
        Returns how many nodes are held."""
        self.grasped_nodes = candidate_nodes(self.positions, self._skin_nodes, self.tool, pose, margin_m)
        self._grasp_offsets = (self.positions[self.grasped_nodes] - pose.position) @ pose.rotation
        self._refresh_inverse_masses()
        return len(self.grasped_nodes)

    def release(self) -> None:
        """Let go of the grasped nodes."""
        self.grasped_nodes = np.zeros(0, dtype=np.int64)
        self._refresh_inverse_masses()

    def _refresh_inverse_masses(self) -> None:
        """1/m, zero for fixed and grasped nodes (the integrator leaves those to the scene and the tool)."""
        self.inv_mass = 1.0 / self.masses_kg
        self.inv_mass[self.fixed_nodes] = 0.0
        self.inv_mass[self.grasped_nodes] = 0.0

    def _move_grasped(self, pose: ToolPose) -> None:
        """Put the grasped nodes where the tool at `pose` holds them, moving at the tool's speed."""
        held = pose.position + self._grasp_offsets @ pose.rotation.T
        self.velocities[self.grasped_nodes] = (held - self.positions[self.grasped_nodes]) / self.frame_period_s
        self.positions[self.grasped_nodes] = held

    def _mass_shares(self, sources: np.ndarray, claims: np.ndarray, used: np.ndarray, old_count: int) -> np.ndarray:
        """(N', S) fraction of each source's mass each new node gets (see apply_topology)."""
        total = np.bincount(sources[used], claims[used], old_count)
        count = np.bincount(sources[used], minlength=old_count)
        floor = np.minimum(self.params.min_node_mass_fraction * self.masses_kg.mean() / self.masses_kg,
                           1.0 / np.maximum(count, 1))
        share = np.where(used, np.maximum(claims / np.where(total > 0.0, total, 1.0)[sources], floor[sources]), 0.0)
        norm = np.bincount(sources[used], share[used], old_count)
        return np.where(used, share / np.where(norm > 0.0, norm, 1.0)[sources], 0.0)

    def reset(self) -> None:
        """Back to the rest shape, at rest, with no tool history and nothing grasped; the clock runs on."""
        self.positions = self.mesh.points.copy()
        self.velocities = np.zeros_like(self.positions)
        self._previous_pose: ToolPose | None = None
        if self.grasped_nodes.size:
            self.release()

    def warm_up(self) -> None:
        """Compile the kernels (numba, cached on disk) before a timed loop starts."""
        self._advance(ToolPose(np.full(3, 1e3)), substeps=0)
        self._previous_pose = None
        self._detector().stretches(self.positions)
        estimate_stable_time_step(self.springs, self.masses_kg, self.params.environment_damping_per_s,
                                  self.params.integrator, self.mesh.points, max_iterations=1)

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.params.frame_rate_hz

    def displacement_m(self) -> np.ndarray:
        """|x − x_rest| per node (m)."""
        return np.linalg.norm(self.positions - self.mesh.points, axis=1)

    def kinetic_energy_j(self) -> float:
        """½·Σ m·|v|² (J)."""
        return 0.5 * float((self.masses_kg * (self.velocities ** 2).sum(axis=1)).sum())

    def step_frame(self, pose: ToolPose | None = None) -> FrameResult:
        """Advance one frame with the tool at `pose` (None: no tool). Resets and reports on divergence.

        With `params.tearing`, faces stretched beyond their threshold then open (`tear`).  While nodes
        are grasped the tool holds them instead of pushing (no contact): the force on the tool is the
        tissue's pull on them, and the local model is `_grasp_local_model`'s.
        """
        grasping = pose is not None and self.grasped_nodes.size > 0
        if grasping:
            self._move_grasped(pose)
        liver_force, box_gaps = self._advance(None if grasping else pose, self.params.substeps)
        if grasping:
            liver_force = -self._force[self.grasped_nodes].sum(axis=0)
        self.time_s += self.frame_period_s
        divergence = self._check_divergence()
        if divergence is not None:
            self.divergences += 1
            self.reset()
            return FrameResult(self.time_s, np.zeros(3), LocalModel.invalid(), divergence)
        torn = self.params.tearing and self._tear()
        if pose is None:
            local_model = LocalModel.invalid()
        elif grasping:
            local_model = self._grasp_local_model(pose, -liver_force)
        else:
            local_model = self._fit_local_model(pose, box_gaps)
        return FrameResult(self.time_s, -liver_force, local_model, None, torn)

    def _grasp_local_model(self, pose: ToolPose, pull_n: np.ndarray) -> LocalModel:
        """The local model of a grasp: a plane with normal n = pull/|pull| that the tool sphere (radius r)
        penetrates by |pull|/λ (λ: contact_stiffness_n_per_m), so that a haptic loop rendering λ·depth·n
        feels the tissue's pull now, and a spring of stiffness λ as the tool moves before the next frame
        (paper §2.5, applied to the pull).  Invalid when the tissue does not pull."""
        magnitude = float(np.linalg.norm(pull_n))
        stiffness = self.params.contact_stiffness_n_per_m
        if not (magnitude > 0.0 and stiffness > 0.0):
            return LocalModel.invalid()
        normal = pull_n / magnitude
        depth = magnitude / stiffness
        point = np.asarray(pose.position) - (self.tool.radius_m - depth) * normal
        return LocalModel("plane", True, point, normal, point, 0.0, depth, True)

    def _detector(self) -> TearDetector:
        """The TearDetector of the current mesh and thresholds (rebuilt when either changes)."""
        key = (self.topology_version, self.params.tear_strain_parenchyma, self.params.tear_strain_capsule)
        if self._tear_detector is None or self._tear_detector[0] != key:
            self._tear_detector = (key, TearDetector(self.mesh.points, self.mesh.tets, self.capsule_triangles,
                                                     key[1], key[2]))
        return self._tear_detector[1]

    def _tear(self) -> bool:
        """Open the faces stretched beyond the tearing thresholds; True when the mesh changed."""
        params = self.params
        change = tear(self.mesh.points, self.mesh.tets, self.positions, self.capsule_triangles,
                      params.tear_strain_parenchyma, params.tear_strain_capsule, detector=self._detector())
        if change is None:
            return False
        self.apply_topology(change)
        return True

    def _advance(self, pose: ToolPose | None, substeps: int) -> tuple[np.ndarray, tuple]:
        """Run `substeps` steps with the tool moving from the previous pose to `pose`.

        Returns the contact force on the liver (N) and the candidate skin nodes with the box tool's
        per-node (gap, point, direction).
        """
        shape = self.tool
        springs = self.springs
        core_a = core_b = velocity = np.zeros(3)
        axes = np.eye(3)
        kind = kernels.TOOL_NONE
        nodes = np.zeros(0, dtype=np.int64)
        if pose is not None:
            kind = TOOL_KINDS[shape.kind]
            core_a, core_b = tool_core(shape, pose)
            axes = np.ascontiguousarray(pose.rotation)
            if self._previous_pose is not None:
                start_a, start_b = tool_core(shape, self._previous_pose)
                if np.linalg.norm(core_a - start_a) <= TOOL_JUMP_M:
                    velocity = (core_a - start_a) / self.frame_period_s
                    core_a, core_b = start_a, start_b
            reach = self.local_model_reach_m + float(np.linalg.norm(velocity)) * self.frame_period_s
            nodes = candidate_nodes(self.positions, self._skin_nodes, shape, pose, reach)
        self._previous_pose = pose
        gap = np.full(len(nodes), np.inf)
        point = np.zeros((len(nodes), 3))
        direction = np.zeros((len(nodes), 3))
        liver_force = kernels.run_frame(
            self.positions, self.velocities, self.inv_mass, springs.node_i, springs.node_j,
            springs.rest_length_m, springs.lambda1_n, springs.lambda2_n, springs.mu_ns_per_m,
            self._partial_forces, self.parallel, self.params.dt_s, substeps,
            self.params.environment_damping_per_s, self._gravity, self.params.integrator == "symplectic_euler",
            kind, core_a, core_b, shape.radius_m, axes, np.asarray(shape.half_extents_m, dtype=np.float64),
            velocity, self.params.contact_stiffness_n_per_m, self.params.contact_damping_ns_per_m,
            self._centre, nodes, self.external_forces_n, self._force, gap, point, direction)
        return liver_force, (nodes, gap, point, direction)

    def _fit_local_model(self, pose: ToolPose, box_gaps: tuple) -> LocalModel:
        """The local model at the end of the frame: from skin triangles for round tools, nodes for a box."""
        shape = self.tool
        if shape.kind == "box":
            nodes, gap, point, direction = box_gaps
            return fit_local_model(gap, point, direction, self.local_model_reach_m, self.local_model_kind,
                                   self.positions[nodes])
        core_a, core_b = tool_core(shape, pose)
        triangles = candidate_triangles(self.positions, self._skin, shape, pose, self.local_model_reach_m)
        gap = np.full(len(triangles), np.inf)
        point = np.zeros((len(triangles), 3))
        direction = np.zeros((len(triangles), 3))
        kernels.surface_gaps(self.positions, self._skin, triangles, core_a, core_b, shape.radius_m,
                             gap, point, direction)
        return fit_local_model(gap, point, direction, self.local_model_reach_m, self.local_model_kind,
                               self.positions[np.unique(self._skin[triangles])])

    def _check_divergence(self) -> str | None:
        """None, or the cause when the state is non-finite or a node outruns max_node_speed_m_s."""
        finite = np.isfinite(self.positions).all() and np.isfinite(self.velocities).all()
        if finite:
            speed = float(np.sqrt((self.velocities ** 2).sum(axis=1)).max())
            if speed <= self.params.max_node_speed_m_s:
                return None
            cause = f"node speed {speed:.3g} m/s above max_node_speed_m_s={self.params.max_node_speed_m_s:g}"
        else:
            cause = "non-finite positions or velocities"
        dt = self.params.dt_s
        if dt > self.stable_dt_s:
            needed = math.ceil(self.frame_period_s / self.stable_dt_s)
            cause += (f"; time step {dt:.3g} s is above the stability bound {self.stable_dt_s:.3g} s of "
                      f"{self.params.integrator} (raise substeps to at least {needed})")
        return f"simulation diverged at t={self.time_s:.4f} s: {cause}; model reset to rest"
