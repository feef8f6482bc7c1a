"""Changing the model's topology (paper §2.6, §3.5; P13, P14): what a tear or a cut hands the model.

A topology change maps the old nodes onto new ones: every new node's state (position, velocity) is
a weighted sum of old nodes' states (`node_sources`, `node_weights`): a node duplicated by a tear
has one source with weight 1, a node created on an edge by a cut has two.  The capsule (Glisson's
capsule) keeps only the skin triangles that came from the original skin; faces opened by a tear or
a cut are parenchyma surface.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from liver_sim.mesh.tetmesh import TET_FACES, face_keys


@dataclass(frozen=True, eq=False)
class TopologyChange:
    """A new mesh and how its nodes come from the old ones.

    rest_points (N', 3) m: rest positions of the new nodes; tets (M', 4) int64, positively oriented;
    capsule_triangles (K', 3) int64: the skin triangles that carry capsule springs, outward oriented;
    node_sources (N', S) int64 and node_weights (N', S) float64: new state = Σ weight · old state
    (unused slots: source 0, weight 0); separated_faces: how many faces were opened.
    """

    rest_points: np.ndarray
    tets: np.ndarray
    capsule_triangles: np.ndarray
    node_sources: np.ndarray
    node_weights: np.ndarray
    separated_faces: int


def _interior_face_pairs(tets: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interior faces as (slot_a, slot_b, key): slot = 4·tet + local face (TET_FACES), slot_a < slot_b."""
    keys = face_keys(tets[:, TET_FACES].reshape(-1, 3), n)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    first = np.flatnonzero(sorted_keys[1:] == sorted_keys[:-1])
    return order[first], order[first + 1], sorted_keys[first]


def interior_face_count(tets: np.ndarray, n: int) -> int:
    """How many faces two tets share (nodes < n)."""
    return len(_interior_face_pairs(tets, n)[0])


def _split_nodes(tets: np.ndarray, n: int, slot_a: np.ndarray, slot_b: np.ndarray,
                 joined: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """New tets and parents when only the face pairs marked `joined` connect their tets' corners."""
    m = len(tets)
    ta, tb = slot_a[joined] // 4, slot_b[joined] // 4
    local_a = TET_FACES[slot_a[joined] % 4]  # (P, 3) local corners of the face in tet a
    local_b = TET_FACES[slot_b[joined] % 4]
    nodes_a = np.take_along_axis(tets[ta], local_a, axis=1)
    nodes_b = np.take_along_axis(tets[tb], local_b, axis=1)
    match = np.argmax(nodes_a[:, :, None] == nodes_b[:, None, :], axis=2)
    corner_a = (4 * ta[:, None] + local_a).ravel()
    corner_b = (4 * tb[:, None] + np.take_along_axis(local_b, match, axis=1)).ravel()
    graph = scipy.sparse.coo_matrix((np.ones(len(corner_a)), (corner_a, corner_b)), shape=(4 * m, 4 * m))
    count, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    corner_node = tets.ravel()
    _, first_corner = np.unique(labels, return_index=True)
    component_node = corner_node[first_corner]
    order = np.lexsort((first_corner, component_node))
    keeps = np.ones(count, dtype=bool)
    keeps[order[1:]] = component_node[order[1:]] != component_node[order[:-1]]
    new_id = np.empty(count, dtype=np.int64)
    new_id[order[keeps[order]]] = component_node[order[keeps[order]]]
    copies = order[~keeps[order]]
    new_id[copies] = n + np.arange(len(copies))
    parent = np.concatenate([np.arange(n, dtype=np.int64), component_node[copies]])
    return new_id[labels].reshape(m, 4), parent


def _overshared_edges(tets: np.ndarray) -> np.ndarray:
    """Skin edges (E, 2), sorted pairs, that lie on more than two skin triangles."""
    n = int(tets.max()) + 1
    faces = tets[:, TET_FACES].reshape(-1, 3)
    _, inverse, counts = np.unique(face_keys(faces, n), return_inverse=True, return_counts=True)
    skin = faces[counts[inverse] == 1]
    edges = np.sort(skin[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    keys, counts = np.unique(edges[:, 0] * n + edges[:, 1], return_counts=True)
    bad = keys[counts > 2]
    return np.stack([bad // n, bad % n], axis=1)


def separate_faces(tets: np.ndarray, cut_faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(new_tets (M,4), parent (N',)): nodes duplicated so that the two tets of each cut face no longer share
    that face; parent[k] = the old node new node k copies (identity for k < N = tets.max()+1, copies appended).

    The corners (tet, node) around each node are grouped into components joined through shared faces
    that are not cut; the component holding the node's lowest corner (4·tet + local index) keeps the
    node, each other one gets a new node, in order of (old node, lowest corner).  Tets keep their order
    and orientation.  cut_faces (F, 3) are node triples in any order; non-interior ones are ignored.

    Manifold fix: a cut face can only open where its nodes are split.  Where the opened faces around an
    edge would leave that edge on more than two skin triangles (a crack pinched at an edge whose two
    ends are both on the crack's border), one cut face around each such edge is left closed (the one
    touching the most such edges, then the lowest face slot), and the split is redone until every skin
    edge lies on exactly two skin triangles.  A cut face whose nodes are not split stays shared.
    """
    tets = np.asarray(tets, dtype=np.int64)
    n = int(tets.max()) + 1
    slot_a, slot_b, keys = _interior_face_pairs(tets, n)
    cut_faces = np.asarray(cut_faces, dtype=np.int64).reshape(-1, 3)
    cut = np.zeros(len(keys), dtype=bool)
    if len(cut_faces):
        valid = (cut_faces.min(axis=1) >= 0) & (cut_faces.max(axis=1) < n)
        cut = np.isin(keys, face_keys(cut_faces[valid], n))
    while True:
        new_tets, parent = _split_nodes(tets, n, slot_a, slot_b, ~cut)
        if not cut.any():
            return new_tets, parent
        bad = np.sort(parent[_overshared_edges(new_tets)], axis=1)
        if not len(bad):
            return new_tets, parent
        open_ids = np.flatnonzero(cut)
        face_nodes = np.sort(np.take_along_axis(tets[slot_a[open_ids] // 4], TET_FACES[slot_a[open_ids] % 4],
                                                axis=1), axis=1)
        edge_pairs = face_nodes[:, [0, 1, 1, 2, 0, 2]].reshape(-1, 3, 2)
        edge_keys = edge_pairs[:, :, 0] * n + edge_pairs[:, :, 1]  # (F, 3) sorted edges of each cut face
        bad_keys = np.unique(bad[:, 0] * n + bad[:, 1])
        on_bad = np.isin(edge_keys, bad_keys)
        touches = on_bad.sum(axis=1)
        closed = False
        for key in bad_keys:
            around = np.flatnonzero((edge_keys == key).any(axis=1))
            if len(around) and cut[open_ids[around]].all():
                choice = around[np.lexsort((slot_a[open_ids[around]], -touches[around]))[0]]
                cut[open_ids[choice]] = False
                closed = True
        if not closed:  # no cut face to close around an over-shared edge: open nothing
            cut[:] = False


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
        slot_a, slot_b, _ = _interior_face_pairs(tets, n)
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
        cap_edges = np.sort(capsule[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        face_sorted = np.sort(self.faces, axis=1)
        face_edges = face_sorted[:, [0, 1, 1, 2, 0, 2]].reshape(-1, 3, 2)
        on_capsule = np.isin(face_edges[:, :, 0] * n + face_edges[:, :, 1],
                             cap_edges[:, 0] * n + cap_edges[:, 1]).any(axis=1)
        self.thresholds = np.where(on_capsule, float(capsule_threshold), float(parenchyma_threshold))
        self._stretch = np.zeros(len(self.faces))
        self._futile: np.ndarray | None = None

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


def tear_faces(rest_points: np.ndarray, tets: np.ndarray, positions: np.ndarray, capsule_triangles: np.ndarray,
               parenchyma_threshold: float, capsule_threshold: float) -> np.ndarray:
    """The interior faces (F, 3) whose stretch (see TearDetector) exceeds their threshold.

    Builds a TearDetector each call; a caller checking every frame keeps one instead.
    """
    return TearDetector(rest_points, tets, capsule_triangles, parenchyma_threshold,
                        capsule_threshold).torn_faces(positions)


def duplication_change(rest_points: np.ndarray, tets: np.ndarray, capsule_triangles: np.ndarray,
                       cut_faces: np.ndarray) -> TopologyChange | None:
    """The change that opens `cut_faces` by duplicating nodes (separate_faces); None if nothing opens."""
    tets = np.asarray(tets, dtype=np.int64)
    new_tets, parent = separate_faces(tets, cut_faces)
    n = int(tets.max()) + 1
    opened = interior_face_count(tets, n) - interior_face_count(new_tets, len(parent))
    if opened == 0:
        return None
    return TopologyChange(
        rest_points=np.ascontiguousarray(np.asarray(rest_points, dtype=np.float64)[parent]),
        tets=new_tets,
        capsule_triangles=_carry_triangles(tets, new_tets, capsule_triangles, n),
        node_sources=parent[:, None].copy(),
        node_weights=np.ones((len(parent), 1)),
        separated_faces=int(opened),
    )


def tear(rest_points: np.ndarray, tets: np.ndarray, positions: np.ndarray, capsule_triangles: np.ndarray,
         parenchyma_threshold: float, capsule_threshold: float,
         detector: TearDetector | None = None) -> TopologyChange | None:
    """Open the faces stretched beyond their threshold (tear_faces, separate_faces); None if none opens.

    `detector`, when given, must be the TearDetector of these rest_points, tets and capsule_triangles;
    it remembers the last set of faces that opened nothing (no node to split), so that the same set
    on the next frames costs no further separation attempt.
    """
    detector = detector or TearDetector(rest_points, tets, capsule_triangles, parenchyma_threshold,
                                        capsule_threshold)
    over = detector.over_threshold(positions)
    if not over.any() or (detector._futile is not None and np.array_equal(over, detector._futile)):
        return None
    change = duplication_change(rest_points, tets, capsule_triangles, detector.faces[over])
    if change is None:
        detector._futile = over.copy()
    return change


def _carry_triangles(tets: np.ndarray, new_tets: np.ndarray, triangles: np.ndarray, n: int) -> np.ndarray:
    """Skin triangles of `tets` renumbered as in `new_tets` (same tets, nodes split), order kept."""
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    keys = face_keys(tets[:, TET_FACES].reshape(-1, 3), n)
    order = np.argsort(keys, kind="stable")
    slots = order[np.searchsorted(keys[order], face_keys(triangles, n))]
    owner = slots // 4
    local = np.argmax(tets[owner][:, None, :] == triangles[:, :, None], axis=2)  # (K, 3)
    return np.take_along_axis(new_tets[owner], local, axis=1)
