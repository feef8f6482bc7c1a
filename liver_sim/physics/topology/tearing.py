"""Tearing (paper §2.6; P13 of docs/paper.md): interior faces stretched beyond a threshold open by node duplication.

Stretch across an interior face with rest unit normal n: s = ½·Σ_t |F_t·n| − 1 over its two tets t, F_t the
tet's deformation gradient (0 at rest, > 0 opened; `TearDetector`).  A face with an edge on a capsule
triangle tears above the capsule's threshold, any other above the parenchyma's.  `tear` opens the faces
over their threshold (topology.separate_faces) and returns the physics.topology.change.TopologyChange the model
applies: every new node copies one old node (source its parent, weight 1), no element is removed, and the
capsule keeps its triangles, renumbered; opened faces are parenchyma surface.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from liver_sim.mesh.tetmesh import TET_FACES, TRIANGLE_EDGES, edge_keys, face_keys, isin_keys, unique_edges
from liver_sim.physics.topology.change import TopologyChange, interior_face_pairs, separate_faces


@numba.njit(cache=True)
def _face_stretches(x, corners, weights, out):
    """out[f] = mean over the face's two tets of |Σ_c weights[f, s, c]·x[corners[f, s, c]]| − 1."""
    for f in range(corners.shape[0]):
        total = 0.0
        for side in range(2):
            gx = gy = gz = 0.0
            for c in range(4):
                node = corners[f, side, c]
                w = weights[f, side, c]
                gx += w * x[node, 0]
                gy += w * x[node, 1]
                gz += w * x[node, 2]
            total += math.sqrt(gx * gx + gy * gy + gz * gz)
        out[f] = 0.5 * total - 1.0


class TearDetector:
    """The interior faces of one rest mesh and their thresholds, precomputed for `stretches`/`faces`.

    Stretch across an interior face with rest unit normal n: s = ½·Σ_t |F_t·n| − 1 over its two tets
    t, F_t = D_t·R_t⁻¹ the tet's deformation gradient (D, R: edge matrices [b−a, c−a, d−a] now and at
    rest), i.e. the mean normal strain of the two tets across the face (0 at rest, > 0 opened).
    F_t·n = Σ_c w_tc·x_c is linear in the four corner positions, so w is precomputed.  A face with an
    edge on a capsule triangle tears above `capsule_threshold`, any other above `parenchyma_threshold`.
    """

    def __init__(self, rest_points: np.ndarray, tets: np.ndarray, capsule_triangles: np.ndarray,
                 parenchyma_threshold: float, capsule_threshold: float):
        rest_points = np.asarray(rest_points, dtype=np.float64)
        tets = np.asarray(tets, dtype=np.int64)
        n = max(int(tets.max()) + 1, len(rest_points))
        slot_a, slot_b, _ = interior_face_pairs(tets, n)
        self.faces = np.take_along_axis(tets[slot_a // 4], TET_FACES[slot_a % 4], axis=1)
        a, b, c = (rest_points[self.faces[:, k]] for k in range(3))
        normal = np.cross(b - a, c - a)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        corners = np.stack([tets[slot_a // 4], tets[slot_b // 4]], axis=1)  # (F, 2, 4)
        p = rest_points[corners]
        e1, e2, e3 = (p[:, :, k] - p[:, :, 0] for k in (1, 2, 3))  # R = [e1 e2 e3]
        rows = np.stack([np.cross(e2, e3), np.cross(e3, e1), np.cross(e1, e2)], axis=2)  # rows of det·R⁻¹
        det = np.einsum("fsi,fsi->fs", e1, rows[:, :, 0])
        g = np.einsum("fski,fi->fsk", rows, normal) / det[:, :, None]  # R⁻¹·n
        self.corners = np.ascontiguousarray(corners)
        self.weights = np.ascontiguousarray(np.concatenate([-g.sum(axis=2, keepdims=True), g], axis=2))
        capsule = np.asarray(capsule_triangles, dtype=np.int64).reshape(-1, 3)
        capsule_edges = edge_keys(unique_edges(capsule, TRIANGLE_EDGES), n) if len(capsule) else np.zeros(0, int)
        face_edges = edge_keys(self.faces[:, TRIANGLE_EDGES], n)
        on_capsule = isin_keys(face_edges, capsule_edges).any(axis=1)
        self.thresholds = np.where(on_capsule, float(capsule_threshold), float(parenchyma_threshold))
        self._stretch = np.zeros(len(self.faces))

    def stretches(self, positions: np.ndarray) -> np.ndarray:
        """Stretch (dimensionless) of every interior face at `positions` (N, 3) m."""
        _face_stretches(np.ascontiguousarray(positions, dtype=np.float64), self.corners, self.weights,
                        self._stretch)
        return self._stretch

    def over_threshold(self, positions: np.ndarray) -> np.ndarray:
        """Mask over `faces`: stretch above the face's threshold."""
        return self.stretches(positions) > self.thresholds

    def torn_faces(self, positions: np.ndarray) -> np.ndarray:
        """The interior faces (F, 3) whose stretch exceeds their threshold."""
        return self.faces[self.over_threshold(positions)]


def duplication_change(rest_points: np.ndarray, tets: np.ndarray, capsule_triangles: np.ndarray,
                       cut_faces: np.ndarray) -> TopologyChange | None:
    """The change that opens `cut_faces` by duplicating nodes (separate_faces); None if nothing opens."""
    tets = np.asarray(tets, dtype=np.int64)
    new_tets, parent, opened = separate_faces(tets, cut_faces)
    if opened == 0:
        return None
    return TopologyChange(
        rest_points=np.ascontiguousarray(np.asarray(rest_points, dtype=np.float64)[parent]),
        tets=new_tets,
        capsule_triangles=_carry_triangles(tets, new_tets, capsule_triangles, int(tets.max()) + 1),
        node_sources=parent[:, None].copy(),
        node_weights=np.ones((len(parent), 1)),
        separated_faces=opened,
    )


def tear(rest_points: np.ndarray, tets: np.ndarray, positions: np.ndarray, capsule_triangles: np.ndarray,
         parenchyma_threshold: float, capsule_threshold: float,
         detector: TearDetector | None = None) -> TopologyChange | None:
    """Open the faces stretched beyond their threshold (TearDetector, separate_faces); None if none opens.
    `detector`, when given, must be the TearDetector of these rest_points, tets and capsule_triangles."""
    detector = detector or TearDetector(rest_points, tets, capsule_triangles, parenchyma_threshold,
                                        capsule_threshold)
    over = faces_to_tear(detector, positions, None)
    return None if over is None else duplication_change(rest_points, tets, capsule_triangles, detector.faces[over])


def faces_to_tear(detector: TearDetector, positions: np.ndarray, futile: np.ndarray | None) -> np.ndarray | None:
    """The mask over `detector.faces` stretched beyond their threshold at `positions`, or None when none is, or
    when it is `futile`: the last set that opened nothing (no node to split) or whose separation raised, which the
    state keeps (State.futile_tear_faces) so that the same set costs no further separation attempt."""
    over = detector.over_threshold(positions)
    if not over.any() or (futile is not None and np.array_equal(over, futile)):
        return None
    return over


def _carry_triangles(tets: np.ndarray, new_tets: np.ndarray, triangles: np.ndarray, n: int) -> np.ndarray:
    """Skin triangles of `tets` renumbered as in `new_tets` (same tets, nodes split), order kept."""
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    keys = face_keys(tets[:, TET_FACES].reshape(-1, 3), n)
    order = np.argsort(keys, kind="stable")
    slots = order[np.searchsorted(keys[order], face_keys(triangles, n))]
    owner = slots // 4
    local = np.argmax(tets[owner][:, None, :] == triangles[:, :, None], axis=2)  # (K, 3)
    return np.take_along_axis(new_tets[owner], local, axis=1)
