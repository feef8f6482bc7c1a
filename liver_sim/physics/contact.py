"""The rigid tool (paper P9, docs/paper.md), its candidate skin elements, and the haptic local model of the touched surface (P11).

The tool tip is the pose's position; the tool frame's +z axis points back along the shaft.
- sphere: a ball of `radius_m` centred on the tip;
- capsule: a shaft of `radius_m` from the tip to tip + `length_m`·z;
- box: the paper's parallelepiped, centred on the tip, axes = the tool frame, `half_extents_m`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from liver_sim.geometry.rotations import quaternion_to_matrix
from liver_sim.local_model import LocalModel
from liver_sim.physics import kernels
from liver_sim.physics.params import ModelParams

TOOL_KINDS = {"sphere": kernels.TOOL_SPHERE, "capsule": kernels.TOOL_CAPSULE, "box": kernels.TOOL_BOX}


@dataclass(frozen=True)
class ToolShape:
    """Shape of the rigid tool, in metres, in the tool frame."""

    kind: str = "sphere"
    radius_m: float = 0.015
    length_m: float = 0.05
    half_extents_m: tuple = (0.01, 0.01, 0.01)

    def __post_init__(self):
        if self.kind not in TOOL_KINDS:
            raise ValueError(f"parameter tool.kind must be one of {tuple(TOOL_KINDS)}, got {self.kind!r}")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise ValueError(f"parameter tool.radius_m must be > 0, got {self.radius_m!r}")
        if not (math.isfinite(self.length_m) and self.length_m >= 0.0):
            raise ValueError(f"parameter tool.length_m must be >= 0, got {self.length_m!r}")
        if len(self.half_extents_m) != 3 or not all(math.isfinite(h) and h > 0 for h in self.half_extents_m):
            raise ValueError(f"parameter tool.half_extents_m must be three numbers > 0, got {self.half_extents_m!r}")

    @property
    def bounding_radius_m(self) -> float:
        """Radius of a ball about the tool's core midpoint that holds the whole tool."""
        if self.kind == "box":
            return float(np.linalg.norm(self.half_extents_m))
        if self.kind == "capsule":
            return self.radius_m + self.length_m / 2.0
        return self.radius_m


@dataclass(frozen=True)
class ToolPose:
    """Tool tip position (m) and orientation (unit quaternion x, y, z, w) in the liver frame."""

    position: np.ndarray
    orientation_xyzw: tuple = (0.0, 0.0, 0.0, 1.0)

    @property
    def rotation(self) -> np.ndarray:
        """3×3 rotation matrix whose columns are the tool axes in the liver frame."""
        return quaternion_to_matrix(self.orientation_xyzw)


def tool_core(shape: ToolShape, pose: ToolPose) -> tuple[np.ndarray, np.ndarray]:
    """The tool's core segment (a, b) in the liver frame: a point for sphere and box, the shaft for a capsule."""
    a = np.asarray(pose.position, dtype=np.float64)
    if shape.kind == "capsule":
        return a, a + pose.rotation[:, 2] * shape.length_m
    return a, a.copy()


def candidate_nodes(points: np.ndarray, skin_nodes: np.ndarray, shape: ToolShape, pose: ToolPose,
                    reach_m: float) -> np.ndarray:
    """Sorted skin nodes within the tool's bounding radius + `reach_m` of its core midpoint (a distance
    test on every skin node: cheaper, per frame, than building a k-d tree of the moving skin)."""
    a, b = tool_core(shape, pose)
    offsets = points[skin_nodes] - (a + b) / 2.0
    near = np.einsum("ij,ij->i", offsets, offsets) <= (shape.bounding_radius_m + reach_m) ** 2
    return np.sort(skin_nodes[near])


def candidate_triangles(points: np.ndarray, skin: np.ndarray, shape: ToolShape, pose: ToolPose,
                        reach_m: float) -> np.ndarray:
    """Sorted skin triangles that may come within `reach_m` of the tool: centroid within the tool's bounding
    radius + the largest circumradius + `reach_m` of its core midpoint."""
    a, b = tool_core(shape, pose)
    corners = points[skin]
    centroids = corners.mean(axis=1)
    spread = corners - centroids[:, None, :]
    circumradius = math.sqrt(np.einsum("ijk,ijk->ij", spread, spread).max()) if len(skin) else 0.0
    offsets = centroids - (a + b) / 2.0
    near = np.einsum("ij,ij->i", offsets, offsets) <= (shape.bounding_radius_m + circumradius + reach_m) ** 2
    return np.flatnonzero(near)


def fit_local_model(gap: np.ndarray, point: np.ndarray, direction: np.ndarray, reach_m: float,
                    kind: str = "plane", skin_points: np.ndarray | None = None) -> LocalModel:
    """Fit the local model from per-candidate contact geometry of the last physics step.

    In contact (some gap < 0): the plane passes through the depth-weighted mean of the contact
    points, its normal the opposite of the depth-weighted mean push direction.  Out of contact but
    within `reach_m`: the plane touches the nearest surface point, facing the tool.  Beyond: invalid.
    kind 'sphere' also fits a sphere (least squares) through `skin_points` near the contact and keeps
    it when it is convex toward the tool (its centre lies behind the plane); otherwise the plane.
    """
    if gap.size == 0 or gap.min() > reach_m:
        return LocalModel.invalid()
    touching = gap < 0.0
    if touching.any():
        depth = -gap[touching]
        plane_point = (depth[:, None] * point[touching]).sum(axis=0) / depth.sum()
        push = (depth[:, None] * direction[touching]).sum(axis=0)
        deepest = float(depth.max())
    else:
        nearest = int(np.argmin(gap))
        plane_point = point[nearest]
        push = direction[nearest]
        deepest = 0.0
    norm = np.linalg.norm(push)
    if not norm > 0.0:
        return LocalModel.invalid()
    normal = -push / norm
    plane = LocalModel("plane", True, plane_point, normal, plane_point, 0.0, deepest, bool(touching.any()))
    if kind != "sphere" or skin_points is None or len(skin_points) < 4:
        return plane
    centre, radius = fit_sphere(skin_points)
    if not (math.isfinite(radius) and (centre - plane_point) @ normal < 0.0 and radius < 1.0):
        return plane
    return LocalModel("sphere", True, plane_point, normal, centre, radius, deepest, plane.in_contact)


def fit_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic least-squares sphere |p − c|² = r² through the points: (centre, radius); radius inf if flat."""
    design = np.column_stack([2.0 * points, np.ones(len(points))])
    rhs = (points * points).sum(axis=1)
    solution, _, rank, _ = np.linalg.lstsq(design, rhs, rcond=None)
    if rank < 4:
        return points.mean(axis=0), math.inf
    centre = solution[:3]
    return centre, float(math.sqrt(max(solution[3] + centre @ centre, 0.0)))


#: A tool that moves farther than this in one frame is taken as re-placed, not as moving (m).
TOOL_JUMP_M = 0.05


def tool_state(shape: ToolShape, pose: ToolPose | None, previous: ToolPose | None, params: ModelParams,
               reach_m: float, positions: np.ndarray, skin_nodes: np.ndarray,
               inward_point: np.ndarray) -> kernels.ToolState:
    """The tool over one frame for kernels.run_frame (pose None: no tool).

    Its core moves at constant velocity (core − previous core)/frame period from where `previous` held
    it to where `pose` holds it; a jump beyond TOOL_JUMP_M is a re-placed tool, at rest at `pose`.
    Candidates: the skin nodes within its bounding radius + `reach_m` + the distance moved; contact
    law: params.contact_stiffness_n_per_m, params.contact_damping_ns_per_m (Eq. 3).
    """
    core_a = core_b = velocity = np.zeros(3)
    axes = np.eye(3)
    kind = kernels.TOOL_NONE
    nodes = np.zeros(0, dtype=np.int64)
    period = 1.0 / params.frame_rate_hz
    if pose is not None:
        kind = TOOL_KINDS[shape.kind]
        core_a, core_b = tool_core(shape, pose)
        axes = np.ascontiguousarray(pose.rotation)
        if previous is not None:
            start_a, start_b = tool_core(shape, previous)
            if np.linalg.norm(core_a - start_a) <= TOOL_JUMP_M:
                velocity = (core_a - start_a) / period
                core_a, core_b = start_a, start_b
        nodes = candidate_nodes(positions, skin_nodes, shape, pose, reach_m + float(np.linalg.norm(velocity)) * period)
    return kernels.ToolState(kind, core_a, core_b, shape.radius_m, axes,
                             np.asarray(shape.half_extents_m, dtype=np.float64), velocity,
                             params.contact_stiffness_n_per_m, params.contact_damping_ns_per_m, inward_point, nodes,
                             np.full(len(nodes), np.inf), np.zeros((len(nodes), 3)), np.zeros((len(nodes), 3)))


def surface_local_model(shape: ToolShape, pose: ToolPose, state: kernels.ToolState, positions: np.ndarray,
                        skin: np.ndarray, reach_m: float, kind: str) -> LocalModel:
    """The local model at the end of a frame (fit_local_model): from the skin triangles near a round
    tool, from the box's candidate nodes (`state`, as kernels.run_frame left them) for a box."""
    if shape.kind == "box":
        return fit_local_model(state.gap, state.point, state.direction, reach_m, kind, positions[state.candidates])
    core_a, core_b = tool_core(shape, pose)
    triangles = candidate_triangles(positions, skin, shape, pose, reach_m)
    gap = np.full(len(triangles), np.inf)
    point = np.zeros((len(triangles), 3))
    direction = np.zeros((len(triangles), 3))
    kernels.surface_gaps(positions, skin, triangles, core_a, core_b, shape.radius_m, gap, point, direction)
    return fit_local_model(gap, point, direction, reach_m, kind, positions[np.unique(skin[triangles])])


def pull_local_model(pose: ToolPose, pull_n: np.ndarray, stiffness_n_per_m: float, radius_m: float) -> LocalModel:
    """The local model of a grasp: a plane with normal n = pull/|pull| that the tool sphere (radius r)
    penetrates by |pull|/λ (λ: the contact stiffness), so that a haptic loop rendering λ·depth·n feels
    the tissue's pull now, and a spring of stiffness λ as the tool moves before the next frame (paper
    §2.5, applied to the pull).  Invalid when the tissue does not pull."""
    magnitude = float(np.linalg.norm(pull_n))
    if not (magnitude > 0.0 and stiffness_n_per_m > 0.0):
        return LocalModel.invalid()
    normal = pull_n / magnitude
    depth = magnitude / stiffness_n_per_m
    point = np.asarray(pose.position) - (radius_m - depth) * normal
    return LocalModel("plane", True, point, normal, point, 0.0, depth, True)
