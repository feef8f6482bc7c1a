"""Cutting along the tool's swept path (paper §3.5; P14, R5 of docs/paper.md): split the crossed tets, open the cut.

The blade is the tool-tip path (P, 3), in the deformed frame, swept along one fixed blade direction d
(by default the inward normal of the skin around the path, made perpendicular to the path's chord):
a ribbon of planar quads, one per path segment, reaching from `depth_m` above the path (so that a
tip pressed into the skin still cuts the skin above it) down to `depth_m` below it.

Splitting: every node gets φ, its signed distance to the ribbon's surface seen along d (distance in the
plane ⟂ d to the projected path polyline; beyond the path's ends, to the end segments' lines).  Each
edge whose ends have opposite signs gets a new node where the linear interpolation of φ vanishes, at
parameter t; a node is first snapped onto the cut (φ := 0) when such a crossing falls within
`snap_fraction` of the edge from it, so every t lies in [snap_fraction, 1 − snap_fraction].  The
crossed tets are then bisected edge by edge (split edges taken in one global order, so neighbouring
tets split their shared faces alike): inside each tet the cut is the plane φ = 0 of its linear φ,
exactly the ribbon's plane where one path segment crosses the tet, and every piece keeps a positive
volume of at least snap_fraction³ of its tet's.  Finally the faces lying on the cut between pieces on
opposite sides are separated by `separate_faces` (node duplication, no element removed).

Extent: a face on the cut is opened when it reaches into the path's length (measured along the
projected path; faces at the two ends are opened whole, so the cut overshoots each end by less than one
element), all its corners lie below `depth_m` above the path, and at least one lies within `depth_m`
below it (faces at the bottom are opened whole too).  Overshooting rather than stopping short matters
on a coarse mesh: a node is only duplicated where the cut passes all around it.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from liver_sim.mesh.tetmesh import TET_EDGES, TET_FACES, face_keys, isin_keys, skin_slots, unique_edges
from liver_sim.physics.topology.change import TopologyChange, interior_face_pairs, separate_pairs, split_skin_slots

#: A crossing closer than this fraction of its edge to an end node is moved onto that node: no piece of a
#: split tet is thinner than this, so no new spring is much shorter (stiffer) than the old ones.
SNAP_FRACTION = 0.25


class Ribbon:
    """The path (P, 3) m swept along the unit blade direction d: `locate` gives (φ, s, h) of points."""

    def __init__(self, path_m: np.ndarray, direction: np.ndarray):
        self.direction = direction / np.linalg.norm(direction)
        helper = np.eye(3)[np.argmin(np.abs(self.direction))]
        e1 = np.cross(self.direction, helper)
        e1 /= np.linalg.norm(e1)
        self.basis = np.stack([e1, np.cross(self.direction, e1)], axis=1)  # (3, 2)
        flat = path_m @ self.basis
        step = np.linalg.norm(np.diff(flat, axis=0), axis=1)
        keep = np.concatenate([[True], step > 1e-9 * max(float(step.sum()), 1e-300)])
        self.path_m = path_m[keep]
        self.flat = flat[keep]
        self.height_m = self.path_m @ self.direction
        seg = np.diff(self.flat, axis=0)
        self.seg_length_m = np.linalg.norm(seg, axis=1)
        self.seg_dir = seg / self.seg_length_m[:, None] if len(seg) else seg
        self.seg_normal = np.stack([-self.seg_dir[:, 1], self.seg_dir[:, 0]], axis=1)
        self.start_m = np.concatenate([[0.0], np.cumsum(self.seg_length_m)])
        self.length_m = float(self.start_m[-1])

    def locate(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(φ, s, h) of points (k, 3): signed distance (m) to the swept path, arc length (m) along the
        projected path (< 0 before its start, > length_m after its end), depth (m) below the path along d."""
        q = points_m @ self.basis
        rel = q[:, None, :] - self.flat[None, :-1, :]  # (k, S, 2)
        along = np.einsum("ksj,sj->ks", rel, self.seg_dir)
        across = np.einsum("ksj,sj->ks", rel, self.seg_normal)
        clipped = np.clip(along, 0.0, self.seg_length_m)
        dist = np.hypot(along - clipped, across)
        rows = np.arange(len(q))
        seg = np.argmin(dist, axis=1)
        a, c, x = along[rows, seg], clipped[rows, seg], across[rows, seg]
        last = len(self.seg_length_m) - 1
        beyond_start = (seg == 0) & (a < 0)
        beyond_end = (seg == last) & (a > self.seg_length_m[seg])
        s = self.start_m[seg] + np.where(beyond_start | beyond_end, a, c)
        phi = x.copy()
        corner = ~(beyond_start | beyond_end) & ((a < 0) | (a > self.seg_length_m[seg]))
        if corner.any():  # nearest to an inner vertex: sign from the mean normal of its two segments
            v = seg[corner] + (a[corner] > 0)
            to_vertex = q[corner] - self.flat[v]
            side = np.einsum("kj,kj->k", to_vertex, self.seg_normal[v - 1] + self.seg_normal[v])
            phi[corner] = np.where(side >= 0, 1.0, -1.0) * np.linalg.norm(to_vertex, axis=1)
        frac = c / self.seg_length_m[seg]
        path_height = (1 - frac) * self.height_m[seg] + frac * self.height_m[seg + 1]
        return phi, s, points_m @ self.direction - path_height


def default_blade_direction(positions: np.ndarray, tets: np.ndarray, path_m: np.ndarray) -> np.ndarray:
    """Default blade direction: minus the area-weighted mean outward normal of the (deformed) skin
    triangles near the path (Gaussian weight of width one mean edge), made perpendicular to the chord."""
    positions = np.asarray(positions, dtype=np.float64)
    path_m = np.asarray(path_m, dtype=np.float64).reshape(-1, 3)
    skin = _skin(np.asarray(tets, dtype=np.int64), len(positions))
    corners = positions[skin]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # 2 × area × n
    edge_m = float(np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1).mean())
    dist = _distance_to_polyline(corners.mean(axis=1), path_m)
    weight = np.exp(-(dist / edge_m) ** 2)
    if weight.sum() <= 0.0:
        weight = (dist == dist.min()).astype(np.float64)
    d = -(weight[:, None] * normals).sum(axis=0)
    chord = path_m[-1] - path_m[0]
    if np.linalg.norm(chord) > 0:
        chord = chord / np.linalg.norm(chord)
        d -= (d @ chord) * chord
    norm = np.linalg.norm(d)
    if norm < 1e-12:
        raise ValueError("no blade direction: the skin normal near the path is parallel to the path")
    return d / norm


def cut_along_path(rest_points: np.ndarray, tets: np.ndarray, positions: np.ndarray,
                   capsule_triangles: np.ndarray, path_m: np.ndarray, depth_m: float,
                   blade_direction: np.ndarray | None = None,
                   snap_fraction: float = SNAP_FRACTION) -> TopologyChange | None:
    """Cut the mesh along the ribbon of `path_m` (P, 3, deformed frame) down to `depth_m` (see module doc).

    blade_direction: the sweep direction (into the organ); None: `default_blade_direction`.  Returns the
    TopologyChange (new nodes on edges: sources (a, b), weights (1 − t, t); duplicated nodes: their
    parent's), or None when the path has fewer than two distinct points or no face opens.

    Phases: the tets near the ribbon (`_tet_boxes`, `_boxes_meet`), the ribbon coordinates of their
    nodes (`_ribbon_coordinates`), the edges to split (`_edges_to_split`), the bisected tets (`_bisect`),
    the faces on the cut (`_faces_on_cut`), and the change that opens them (`_opening_change`).
    """
    rest_points = np.asarray(rest_points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    positions = np.asarray(positions, dtype=np.float64)
    path_m = np.asarray(path_m, dtype=np.float64).reshape(-1, 3)
    if not 0.0 < snap_fraction < 0.5:
        raise ValueError(f"snap_fraction must lie in (0, 0.5), got {snap_fraction}")
    if len(path_m) < 2 or not np.isfinite(path_m).all() or depth_m <= 0:
        return None
    boxes = _tet_boxes(positions, tets)
    if not _boxes_meet(boxes, path_m, depth_m).any():
        return None
    direction = (default_blade_direction(positions, tets, path_m) if blade_direction is None
                 else np.asarray(blade_direction, dtype=np.float64))
    ribbon = Ribbon(path_m, direction)
    if len(ribbon.seg_length_m) == 0:
        return None
    inner = _boxes_meet(boxes, path_m, np.abs(ribbon.direction) * depth_m)
    if not inner.any():
        return None
    n = len(rest_points)
    phi, node_s, node_h, outer = _ribbon_coordinates(ribbon, positions, tets, inner)
    split = _edges_to_split(ribbon, positions, tets[inner], outer, phi, node_s, node_h, depth_m, snap_fraction)
    if split is None:
        return None
    pieces = _bisect(tets, split.edges, n)
    total = n + len(split.edges)
    slot_a, slot_b, cut = _faces_on_cut(pieces, total, ribbon.length_m, depth_m,
                                        np.concatenate([phi, np.zeros(len(split.edges))]),
                                        np.concatenate([node_s, split.s_m]), np.concatenate([node_h, split.h_m]))
    if not cut.any():
        return None
    return _opening_change(rest_points, capsule_triangles, pieces, slot_a, slot_b, cut, split)


class _Split(NamedTuple):
    """The edges (K, 2) to split, sorted pairs, at parameter t from edges[:, 0], with the ribbon
    coordinates s, h (m) of the new nodes."""

    edges: np.ndarray
    t: np.ndarray
    s_m: np.ndarray
    h_m: np.ndarray


def _tet_boxes(positions: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) (M, 3) m: the tets' bounding boxes at `positions`."""
    corners = positions[tets]
    low = np.minimum(np.minimum(corners[:, 0], corners[:, 1]), np.minimum(corners[:, 2], corners[:, 3]))
    high = np.maximum(np.maximum(corners[:, 0], corners[:, 1]), np.maximum(corners[:, 2], corners[:, 3]))
    return low, high


def _boxes_meet(boxes: tuple[np.ndarray, np.ndarray], path_m: np.ndarray, reach_m) -> np.ndarray:
    """Mask over the tets: its box meets the path's box grown by `reach_m` (m, scalar or per axis)."""
    low, high = path_m.min(axis=0) - reach_m, path_m.max(axis=0) + reach_m
    return ((boxes[0] <= high) & (boxes[1] >= low)).all(axis=1)


def _ribbon_coordinates(ribbon: Ribbon, positions: np.ndarray, tets: np.ndarray,
                        inner: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(φ, s, h, outer): Ribbon.locate of the nodes of the `inner` tets' node neighbours (`outer` tets), so
    that every tet holding an edge of an inner tet sees true signs; φ = 1, s = h = NaN elsewhere."""
    n = len(positions)
    touched = np.zeros(n, dtype=bool)
    touched[tets[inner]] = True
    outer = tets[touched[tets].any(axis=1)]
    nodes = np.unique(outer)
    phi = np.ones(n)
    node_s = np.full(n, np.nan)
    node_h = np.full(n, np.nan)
    phi[nodes], node_s[nodes], node_h[nodes] = ribbon.locate(positions[nodes])
    return phi, node_s, node_h, outer


def _edges_to_split(ribbon: Ribbon, positions: np.ndarray, inner_tets: np.ndarray, outer: np.ndarray,
                    phi: np.ndarray, node_s: np.ndarray, node_h: np.ndarray, depth_m: float,
                    snap_fraction: float) -> _Split | None:
    """The edges of the outer tets that φ crosses (after `_snap`, which zeroes φ in place) and that lie
    in an inner tet split by the cut: φ changes sign in it and one corner of its cut lies in the ribbon
    (0 ≤ s ≤ length, |h| ≤ depth_m); none when φ vanishes at nodes only.  None when φ neither crosses
    an edge nor vanishes at a node."""
    n = len(positions)
    edges = unique_edges(outer, TET_EDGES)
    crossing, t = _snap(phi, edges, snap_fraction)
    if not crossing.any() and not (phi[outer] == 0).any():
        return None
    cross_edges, t = edges[crossing], t[crossing]
    if not len(cross_edges):  # φ vanishes at nodes only: the cut can only open existing faces
        return _Split(cross_edges, np.zeros(0), np.zeros(0), np.zeros(0))
    cross_points = (1 - t)[:, None] * positions[cross_edges[:, 0]] + t[:, None] * positions[cross_edges[:, 1]]
    _, cross_s, cross_h = ribbon.locate(cross_points)

    def in_band(s, h):
        return (s >= 0) & (s <= ribbon.length_m) & (np.abs(h) <= depth_m)

    edge_keys = cross_edges[:, 0] * n + cross_edges[:, 1]
    local = np.sort(inner_tets[:, TET_EDGES], axis=2)
    local_keys = local[:, :, 0] * n + local[:, :, 1]
    where = np.clip(np.searchsorted(edge_keys, local_keys), 0, len(edge_keys) - 1)
    crossed = edge_keys[where] == local_keys
    zero_in_band = (phi == 0) & in_band(node_s, node_h)
    active = crossed.any(axis=1) & ((crossed & in_band(cross_s, cross_h)[where]).any(axis=1)
                                    | zero_in_band[inner_tets].any(axis=1))
    split = np.unique(where[active][crossed[active]])
    return _Split(cross_edges[split], t[split], cross_s[split], cross_h[split])


def _faces_on_cut(pieces: np.ndarray, total: int, length_m: float, depth_m: float, phi: np.ndarray,
                  s_m: np.ndarray, h_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(slot_a, slot_b, cut): the interior face pairs of `pieces` (interior_face_pairs) and the mask of
    those on the cut: shared by pieces lying on opposite sides (sign of φ at their nodes), with every
    corner in the extent (see the module doc; s, h: the nodes' ribbon coordinates)."""
    sign = np.sign(phi[pieces])
    side = np.where((sign >= 0).all(axis=1), 1, 0) - np.where((sign <= 0).all(axis=1), 1, 0)
    faces = pieces[:, TET_FACES].reshape(-1, 3)
    slot_a, slot_b, _ = interior_face_pairs(pieces, total)
    candidate = faces[slot_a]
    fs, fh = s_m[candidate], h_m[candidate]
    fh_min = np.minimum(np.minimum(fh[:, 0], fh[:, 1]), fh[:, 2])
    fs_min = np.minimum(np.minimum(fs[:, 0], fs[:, 1]), fs[:, 2])
    fs_max = np.maximum(np.maximum(fs[:, 0], fs[:, 1]), fs[:, 2])
    cut = ((side[slot_a // 4] * side[slot_b // 4] == -1) & (fh_min >= -depth_m) & (fh_min <= depth_m)
           & (fs_max >= 0) & (fs_min <= length_m))
    return slot_a, slot_b, cut


def _opening_change(rest_points: np.ndarray, capsule_triangles: np.ndarray, pieces: np.ndarray,
                    slot_a: np.ndarray, slot_b: np.ndarray, cut: np.ndarray, split: _Split) -> TopologyChange | None:
    """The TopologyChange that opens the faces `cut` between `pieces` (separate_pairs); None if none opens.
    Node k < N keeps old node k; new node N + i lies on split.edges[i] at split.t[i]."""
    n = len(rest_points)
    new_tets, parent, shared = separate_pairs(pieces, n + len(split.edges), slot_a, slot_b, cut)
    opened = int((~shared).sum())
    if opened == 0:
        return None
    sources = np.concatenate([np.stack([np.arange(n), np.zeros(n, np.int64)], axis=1), split.edges])
    weights = np.concatenate([np.column_stack([np.ones(n), np.zeros(n)]),
                              np.column_stack([1 - split.t, split.t])])
    rest_new = np.concatenate([rest_points, (1 - split.t)[:, None] * rest_points[split.edges[:, 0]]
                               + split.t[:, None] * rest_points[split.edges[:, 1]]])
    sources, weights, rest_new = sources[parent], weights[parent], rest_new[parent]
    return TopologyChange(
        rest_points=rest_new,
        tets=new_tets,
        capsule_triangles=_capsule_pieces(new_tets[:, TET_FACES].reshape(-1, 3)[
            split_skin_slots(len(pieces), slot_a, slot_b, shared)], sources, weights, capsule_triangles, n),
        node_sources=sources,
        node_weights=weights,
        separated_faces=opened,
    )


def _snap(phi: np.ndarray, edges: np.ndarray, snap_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero φ at nodes a crossing falls too close to (in place); (crossing mask, t from edges[:, 0])."""
    while True:
        pa, pb = phi[edges[:, 0]], phi[edges[:, 1]]
        crossing = pa * pb < 0
        t = np.where(crossing, pa / np.where(crossing, pa - pb, 1.0), 0.0)
        near_a = crossing & (t < snap_fraction)
        near_b = crossing & (t > 1 - snap_fraction)
        if not (near_a.any() or near_b.any()):
            return crossing, t
        phi[edges[near_a, 0]] = 0.0
        phi[edges[near_b, 1]] = 0.0


def _bisect(tets: np.ndarray, split_edges: np.ndarray, n: int) -> np.ndarray:
    """Tets bisected at new nodes n + i on split_edges[i] (sorted unique pairs), edges in that order.

    Each tet is split at its first split edge (a, b): (…a…b…) → (…a…m…) and (…m…b…), both keeping
    the orientation; the pieces again until none holds a split edge.  Shared faces split alike.
    """
    if not len(split_edges):
        return tets
    total = n + len(split_edges)
    split_keys = split_edges[:, 0] * total + split_edges[:, 1]
    done = []
    work = tets
    while len(work):
        ends = work[:, TET_EDGES]
        keys = ends.min(axis=2) * total + ends.max(axis=2)
        where = np.clip(np.searchsorted(split_keys, keys), 0, len(split_keys) - 1)
        found = split_keys[where] == keys
        rank = np.where(found, where, len(split_keys))
        choice = np.argmin(rank, axis=1)
        has = found.any(axis=1)
        done.append(work[~has])
        work, choice = work[has], choice[has]
        rows = np.arange(len(work))
        middle = n + rank[has][rows, choice]
        first, second = work.copy(), work.copy()
        first[rows, TET_EDGES[choice, 1]] = middle
        second[rows, TET_EDGES[choice, 0]] = middle
        work = np.concatenate([first, second])
    return np.concatenate(done)


def _skin(tets: np.ndarray, n: int) -> np.ndarray:
    """The faces (K, 3) on exactly one tet, outward, in tet order (as TetMesh.skin, unsorted)."""
    return tets[:, TET_FACES].reshape(-1, 3)[np.sort(skin_slots(tets, n))]


def _capsule_pieces(skin: np.ndarray, sources: np.ndarray, weights: np.ndarray,
                    capsule_triangles: np.ndarray, n: int) -> np.ndarray:
    """The skin triangles lying in an old capsule triangle: their corners' old source nodes are exactly
    that triangle's three nodes."""
    capsule_triangles = np.asarray(capsule_triangles, dtype=np.int64).reshape(-1, 3)
    support = np.where(weights[skin] > 0, sources[skin], n).reshape(len(skin), -1)
    support.sort(axis=1)
    fresh = np.concatenate([np.ones((len(skin), 1), bool), support[:, 1:] != support[:, :-1]], axis=1)
    fresh &= support < n
    three = fresh.sum(axis=1) == 3
    nodes = support[three][fresh[three]].reshape(-1, 3)
    keep = np.zeros(len(skin), dtype=bool)
    keep[three] = isin_keys(face_keys(nodes, n), face_keys(capsule_triangles, n))
    return skin[keep]


def _distance_to_polyline(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance (m) of points (k, 3) to the polyline path (P, 3)."""
    if len(path) == 1:
        return np.linalg.norm(points - path[0], axis=1)
    a, seg = path[:-1], np.diff(path, axis=0)
    length2 = np.maximum((seg ** 2).sum(axis=1), 1e-300)
    rel = points[:, None, :] - a[None]
    frac = np.clip(np.einsum("ksj,sj->ks", rel, seg) / length2, 0.0, 1.0)
    return np.linalg.norm(rel - frac[..., None] * seg[None], axis=2).min(axis=1)
