"""The rigid tool (paper P9, docs/paper.md), its candidate skin elements, and the haptic local model of the touched
surface (P11).

The tool tip is the pose's position; the tool frame's +z axis points back along the shaft.
- sphere: a ball of `radius_m` centred on the tip;
- capsule: a shaft of `radius_m` from the tip to tip + `length_m`·z;
- box: the paper's parallelepiped, centred on the tip, axes = the tool frame, `half_extents_m`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from liver_sim.base.geometry.rotations import quaternion_to_matrix
from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact.kernels import (
    TOOL_BOX,
    TOOL_CAPSULE,
    TOOL_NONE,
    TOOL_SPHERE,
    ToolSweep,
    contact_elements,
    near_triangles,
    probe_geometry,
)
from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tissue.materials import triangle_areas

TOOL_KINDS = {"sphere": TOOL_SPHERE, "capsule": TOOL_CAPSULE, "box": TOOL_BOX}


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
    return near_triangles(points, skin, (a + b) / 2.0, shape.bounding_radius_m + reach_m)


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
#: Largest spacing of a box's contact probes on its faces (m).
BOX_PROBE_SPACING_M = 0.01


def tool_probes(shape: ToolShape, pose: ToolPose) -> tuple[np.ndarray, float]:
    """The tool's contact probes (P, 3) in the liver frame and their radius (m): the sphere's centre; points
    along a capsule's shaft at most radius/2 apart (the union of their balls departs from the capsule by
    < 4 % of its radius); for a box, radius 0 and the points of a grid on its faces at most
    BOX_PROBE_SPACING_M apart, corners and edge midpoints included (a point shell)."""
    tip = np.asarray(pose.position, dtype=np.float64)
    if shape.kind == "sphere":
        return tip[None, :].copy(), shape.radius_m
    rotation = pose.rotation
    if shape.kind == "capsule":
        count = max(1, math.ceil(shape.length_m / (shape.radius_m / 2.0)) + 1)
        along = np.linspace(0.0, shape.length_m, count)
        return tip + along[:, None] * rotation[:, 2], shape.radius_m
    half = np.asarray(shape.half_extents_m, dtype=np.float64)
    axes = [np.linspace(-h, h, max(3, math.ceil(2.0 * h / BOX_PROBE_SPACING_M) + 1)) for h in half]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    on_face = (np.abs(np.abs(grid) - half) <= 1e-12 * half).any(axis=1)
    return tip + grid[on_face] @ rotation.T, 0.0


def tool_sweep(shape: ToolShape, pose: ToolPose | None, previous: ToolPose | None, params: ModelParams,
               reach_m: float, positions: np.ndarray, skin: np.ndarray) -> ToolSweep:
    """The tool over one frame for explicit_kernels.run_frame (pose None: no tool).

    Its probes (tool_probes) move at constant velocity (tip − previous tip)/frame period from where
    `previous` held them to where `pose` holds them; a jump beyond TOOL_JUMP_M is a re-placed tool, at rest
    at `pose`.  Candidates: the skin triangles within reach_m + the distance moved (candidate_triangles);
    contact law: params.contact_stiffness_n_per_m, params.contact_damping_ns_per_m (Eq. 3).
    """
    velocity = np.zeros(3)
    kind = TOOL_NONE
    probes, radius = np.zeros((0, 3)), 0.0
    triangles = np.zeros(0, dtype=np.int64)
    if pose is not None:
        kind = TOOL_KINDS[shape.kind]
        probes, radius = tool_probes(shape, pose)
        if previous is not None:
            moved = np.asarray(pose.position, dtype=np.float64) - np.asarray(previous.position, dtype=np.float64)
            if np.linalg.norm(moved) <= TOOL_JUMP_M:
                velocity = moved * params.frame_rate_hz
                probes, radius = tool_probes(shape, previous)
        triangles = candidate_triangles(positions, skin, shape, pose, reach_m + float(np.linalg.norm(velocity))
                                        / params.frame_rate_hz)
    rows = len(probes) * len(triangles)
    return ToolSweep(kind, np.ascontiguousarray(probes), radius, velocity, params.contact_stiffness_n_per_m,
                     params.contact_damping_ns_per_m, np.ascontiguousarray(skin, dtype=np.int64), triangles,
                     np.zeros((rows, 3), dtype=np.int64), np.zeros((rows, 3)), np.zeros((rows, 3)),
                     np.full(rows, -np.inf), np.zeros(rows), np.zeros((rows, 3)), np.zeros(rows))


def probe_contacts(x: np.ndarray, v: np.ndarray, tool: ToolSweep, shift: np.ndarray, dt: float) -> None:
    """The tool's contact rows (kernels.probe_geometry) with its probes moved by `shift`, in its arrays."""
    probe_geometry(x, v, tool, shift, dt)


#: The surface contact (contact_rows): skin nodes within this of the tool's surface get a row (m), and a face row
#: pushes only the part of its dip beyond this allowance (m), fading out as the face's nodes come into contact.
SURFACE_MARGIN_M = 1e-3
FACE_ALLOWANCE_M = 5e-5
#: A face row fades out as the nearest of its nodes comes within this of the ball's surface (m).
FACE_FADE_M = 2e-4


def contact_rows(x: np.ndarray, v: np.ndarray, tool: ToolSweep, shift: np.ndarray, dt: float,
                 node_area_m2: np.ndarray | None = None, stiffness_per_area_n_per_m3: float = 0.0,
                 multipliers_n: np.ndarray | None = None) -> Contacts:
    """The tool's contacts with the skin for implicit.ImplicitEuler, its probes moved by `shift` (where they are at
    the end of the step), linearised about the skin where its velocity takes it in `dt` (x̂ = x + dt·v, so the
    contacts that touch at the end of the step are those that act): Eq. 3, F = max(0, k·δ + c·δ̇) per element,
    o = δ(x̂) + n·Σ w_a·x̂_a so that δ = o − n·Σ w_a·x_a, s = n·v_tool.

    Without `node_area_m2` (contact_model 'probe', and always for a box, whose probes are points): the rows of
    kernels.probe_geometry with a share, k = share·λ, c = share·μ: one penalty per probe.
    With it (contact_model 'surface'), a ball (sphere, capsule) meets the skin on its true surface, the ball of
    radius r swept along its core segment (the first to the last probe), k = k_A·A per row (k_A
    `stiffness_per_area_n_per_m3`, a pressure per depth, the same on every mesh), c = k·μ/λ:
    * every skin node of the candidate triangles within SURFACE_MARGIN_M of the surface gets a row on it, δ = r −
      |x − c| (c the core's point nearest x), A its `node_area_m2`, rebuilt at every iterate of the step
      (implicit_kernels.surface_rows) and biased by its augmented Lagrange multiplier (`multipliers_n` (N,) N, the
      node's force the last step left: update_multipliers), so that a held contact's penetration vanishes with a
      moderate penalty;
    * a face's row (kernels.probe_geometry's closest point, A its `surface_weight` × the candidates' mean area)
      only as a safety net where the ball sinks into a face whose nodes it does not reach (a small tool on large
      faces): it pushes the dip beyond FACE_ALLOWANCE_M, at full stiffness while its nodes are all FACE_FADE_M or
      more outside the ball, fading to 0 as the nearest one (its depth plus its multiplier over k) reaches the
      ball, so that where the nodes take the contact they alone carry it, as a P1 discretisation of the contact
      does (a face between nodes on the ball dips by up to about L²/(6r), L its longest edge)."""
    ahead = x + dt * v
    probe_contacts(ahead, v, tool, shift, 0.0)
    ratio = tool.damping_ns_per_m / tool.stiffness_n_per_m if tool.stiffness_n_per_m > 0.0 else 0.0
    if node_area_m2 is None or tool.radius_m <= 0.0:
        stiffness = tool.share * tool.stiffness_n_per_m
        return Contacts(*contact_elements(ahead, tool.nodes, tool.weights, tool.normal, tool.depth, stiffness,
                                          tool.share * tool.damping_ns_per_m, tool.velocity_m_s))
    if multipliers_n is None:
        multipliers_n = np.zeros(len(x))
    core = np.stack([tool.probes[0] + shift, tool.probes[-1] + shift])
    nodes, normal, depth = surface_depths(ahead, tool, core)
    node_k = stiffness_per_area_n_per_m3 * node_area_m2[nodes]
    bias = np.divide(multipliers_n[nodes], node_k, out=np.zeros(len(nodes)), where=node_k > 0.0)
    reach = np.full(len(x), -np.inf)  # each node's depth with its multiplier's (its elastic force over k)
    reach[nodes] = depth + bias
    face = tool.skin[tool.triangles]
    fade = np.clip(-reach[face].max(axis=1, initial=-np.inf) / FACE_FADE_M, 0.0, 1.0)
    residual = tool.depth - FACE_ALLOWANCE_M
    area = triangle_areas(ahead, face).mean() if len(face) else 0.0
    row_fade = fade[np.arange(len(residual)) % len(face)] if len(face) else np.zeros(len(residual))
    stiffness = np.where(residual > 0.0, stiffness_per_area_n_per_m3 * tool.surface_weight * area * row_fade, 0.0)
    face_rows = Contacts(*contact_elements(ahead, tool.nodes, tool.weights, tool.normal, residual, stiffness,
                                           stiffness * ratio, tool.velocity_m_s))
    near = depth > -SURFACE_MARGIN_M
    nodes, normal, depth, node_k, bias = nodes[near], normal[near], depth[near], node_k[near], bias[near]
    count, faces = len(nodes), len(face_rows)
    padded = np.full((count, 3), -1, dtype=np.int64)
    padded[:, 0] = nodes
    node_weights = np.zeros((count, 3))
    node_weights[:, 0] = 1.0
    return Contacts(np.concatenate([face_rows.nodes, padded]), np.concatenate([face_rows.weights, node_weights]),
                    np.concatenate([face_rows.normal, normal]),
                    np.concatenate([face_rows.offset_m, depth + bias + np.einsum("ij,ij->i", normal, ahead[nodes])]),
                    np.concatenate([face_rows.normal_speed_m_s, normal @ tool.velocity_m_s]),
                    np.concatenate([face_rows.stiffness_n_per_m, node_k]),
                    np.concatenate([face_rows.damping_ns_per_m, node_k * ratio]),
                    np.concatenate([np.zeros((faces, 2, 3)), np.broadcast_to(core, (count, 2, 3))]),
                    np.concatenate([np.zeros(faces), np.full(count, tool.radius_m)]),
                    np.concatenate([np.zeros((faces, 3)), np.broadcast_to(tool.velocity_m_s, (count, 3))]),
                    np.concatenate([np.zeros(faces), bias]))


def update_multipliers(contacts: Contacts, x: np.ndarray, multipliers_n: np.ndarray) -> None:
    """A tool's augmented Lagrange multipliers (N,) N after a step that ends at x, in place: the node of each of its
    rows on the tool's surface (radius > 0, one per node) gets that row's elastic force k·(o − n·x), clipped at 0
    (its multiplier included in o); every other node 0."""
    multipliers_n[:] = 0.0
    surface = contacts.radius_m > 0.0
    nodes = contacts.nodes[surface, 0]
    along = np.einsum("ij,ij->i", contacts.normal[surface], x[nodes])
    multipliers_n[nodes] = np.maximum(contacts.stiffness_n_per_m[surface] * (contacts.offset_m[surface] - along), 0.0)


def surface_depths(x: np.ndarray, tool: ToolSweep, core: np.ndarray) -> tuple[np.ndarray, ...]:
    """The nodes of the tool's candidate triangles and, for each, its outward normal n = (x − c)/|x − c| from the
    point c of the `core` segment (2, 3) nearest it, and its depth δ = r − |x − c| in the tool's ball (m, negative
    outside); a node on the core itself is left out."""
    nodes = np.unique(tool.skin[tool.triangles]) if len(tool.triangles) else np.zeros(0, np.int64)
    axis = core[1] - core[0]
    length2 = float(axis @ axis)
    points = x[nodes]
    t = np.clip((points - core[0]) @ axis / length2, 0.0, 1.0) if length2 > 0.0 else np.zeros(len(nodes))
    offsets = points - (core[0] + t[:, None] * axis)
    distance = np.linalg.norm(offsets, axis=1)
    keep = distance > 1e-12
    return nodes[keep], offsets[keep] / distance[keep, None], tool.radius_m - distance[keep]


def force_local_model(shape: ToolShape, pose: ToolPose, tool: ToolSweep, force_on_tool_n: np.ndarray,
                      stiffness_n_per_m: float, reach_m: float, kind: str, positions: np.ndarray) -> LocalModel:
    """The local model of the end of a frame, consistent with its contact force F (paper §2.5, P11): in
    contact, the plane with normal F/|F| that the tool sphere (radius r) penetrates by |F|/K, so that the
    haptic loop rendering K·depth feels F at the pose of the frame and a spring of stiffness K as the
    tool moves before the next one (kind 'sphere': a sphere fitted through the candidate triangles'
    nodes, kept when convex toward the tool, with the same normal and depth at the tip).  Without contact
    force, the plane through the nearest probe's surface point facing the tool, moved back until the tool
    does not touch it (depth 0); none within `reach_m`: invalid.  `in_contact`: a force, or a probe
    touching the surface (its push clipped to 0 by the damping of a fast withdrawal)."""
    magnitude = float(np.linalg.norm(force_on_tool_n))
    tip = np.asarray(pose.position, dtype=np.float64)
    radius = shape.radius_m
    if magnitude > 0.0:
        normal = force_on_tool_n / magnitude
        depth = magnitude / stiffness_n_per_m
        point = tip - (radius - depth) * normal
    else:
        finite = np.isfinite(tool.depth)  # the rows: each probe against each candidate triangle
        nearest = int(np.argmax(np.where(finite, tool.depth, -np.inf))) if finite.any() else -1
        if nearest < 0 or -tool.depth[nearest] > reach_m:
            return LocalModel.invalid()
        normal, point, depth = -tool.normal[nearest], tool.point[nearest], 0.0
        point = point - max(radius - float((tip - point) @ normal), 0.0) * normal
    touching = magnitude > 0.0 or bool(((tool.depth > 0.0) & (tool.share > 0.0)).any())
    plane = LocalModel("plane", True, point, normal, point, 0.0, depth, touching, stiffness_n_per_m)
    if kind != "sphere":
        return plane
    nodes = np.unique(tool.skin[tool.triangles])
    if len(nodes) < 4:
        return plane
    centre, sphere_radius = fit_sphere(positions[nodes])
    if not (math.isfinite(sphere_radius) and (centre - point) @ normal < 0.0 and sphere_radius < 1.0):
        return plane
    centre = point - sphere_radius * normal
    return LocalModel("sphere", True, point, normal, centre, sphere_radius, depth, plane.in_contact,
                      stiffness_n_per_m)


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
    return LocalModel("plane", True, point, normal, point, 0.0, depth, True, stiffness_n_per_m)
