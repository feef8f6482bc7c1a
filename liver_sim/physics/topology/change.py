"""Changing the model's topology (paper §2.6, §3.5; P13, P14 of docs/paper.md): what a tear or a cut hands the model.

A topology change maps the old nodes onto new ones: every new node's state (position, velocity) is
a weighted sum of old nodes' states (`node_sources`, `node_weights`): a node duplicated by a tear
has one source with weight 1, a node created on an edge by a cut has two.  The capsule (Glisson's
capsule) keeps only the skin triangles that came from the original skin; faces opened by a tear or
a cut are parenchyma surface.

physics.topology.tearing and physics.topology.cutting build the changes; what both rely on is here: checking a change
(`check_change`), carrying the node state and masses onto the new nodes (`carry_over`), and opening
interior faces by node duplication while keeping the skin manifold (`separate_faces`, `separate_pairs`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.mesh.tetmesh import (
    TET_FACES,
    TetMesh,
    edge_keys,
    face_keys,
    isin_keys,
    key_groups,
)


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


class NodeState(NamedTuple):
    """What a model keeps per node: positions (N, 3) m, velocities (N, 3) m/s, external forces (N, 3) N,
    masses (N,) kg, and the sorted fixed nodes."""

    positions: np.ndarray
    velocities: np.ndarray
    external_forces_n: np.ndarray
    masses_kg: np.ndarray
    fixed_nodes: np.ndarray


def check_change(change: TopologyChange, old_node_count: int, source: str = "topology change") -> TetMesh:
    """The new mesh of `change` (a TetMesh named `source`) once it is known to leave a sound model, else
    ValueError naming the field: node_sources, node_weights (N', S) with sources among the
    `old_node_count` old nodes, finite non-negative weights summing to 1 per row; finite rest_points;
    tets using every node, positively oriented at rest (TetMesh.from_arrays keeps them as they are); a
    watertight skin (every skin edge on two skin triangles traversing it oppositely, so every component
    is closed and manifold at its edges); capsule_triangles among its triangles."""
    sources = np.asarray(change.node_sources)
    weights = np.asarray(change.node_weights, dtype=np.float64)
    count = len(change.rest_points)
    if sources.ndim != 2 or sources.shape != weights.shape or len(sources) != count:
        raise ValueError("topology change: node_sources and node_weights must both be (N', S) "
                         f"with N' = {count} rest points")
    if sources.size and (sources.min() < 0 or sources.max() >= old_node_count):
        raise ValueError(f"topology change: node_sources must index the old nodes 0..{old_node_count - 1}")
    if not (np.isfinite(weights).all() and (weights >= 0.0).all()
            and np.allclose(weights.sum(axis=1), 1.0, rtol=0.0, atol=1e-9)):
        raise ValueError("topology change: node_weights must be finite, non-negative and sum to 1 per node")
    if not np.isfinite(change.rest_points).all():
        raise ValueError("topology change: rest_points must be finite")
    mesh = TetMesh.from_arrays(change.rest_points, change.tets, source=source)
    if len(mesh.points) != count or not np.array_equal(mesh.tets, change.tets):
        raise ValueError("topology change: tets must use every node and be positively oriented at rest")
    directed = mesh.skin[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    forward = np.sort(directed[:, 0] * count + directed[:, 1])
    if (np.diff(forward) == 0).any() or not isin_keys(directed[:, 1] * count + directed[:, 0], forward).all():
        raise ValueError("topology change: the new skin is not watertight (an edge not on exactly two "
                         "oppositely oriented skin triangles)")
    capsule = np.asarray(change.capsule_triangles, dtype=np.int64).reshape(-1, 3)
    if len(capsule) and (capsule.min() < 0 or capsule.max() >= count
                         or not isin_keys(face_keys(capsule, count), face_keys(mesh.skin, count)).all()):
        raise ValueError("topology change: capsule_triangles must be skin triangles of the new mesh")
    return mesh


def carry_over(change: TopologyChange, state: NodeState, source: str, density_kg_m3: float,
               min_node_mass_fraction: float) -> tuple[TetMesh, NodeState]:
    """The new mesh (named `source`) of `change` and the node state carried onto it.

    New positions, velocities: x'_k = Σ w·x[source].  Masses: old node i's mass goes to the new
    nodes that draw on it, in shares ∝ w·(their lumped tet mass at `density_kg_m3`) (mass_shares);
    each old mass is so split exactly: the total is conserved and, for duplicated nodes (one source,
    weight 1), so is the momentum; mass of an old node nothing draws on is spread over all nodes ∝ mass.
    External forces are split with the same shares.  A new node drawing only on fixed nodes is fixed.
    ValueError (check_change) for a change that would not leave a sound model.
    """
    old_count = len(state.positions)
    mesh = check_change(change, old_count, source)
    sources = np.asarray(change.node_sources, dtype=np.int64)
    weights = np.asarray(change.node_weights, dtype=np.float64)
    used = weights > 0.0
    claims = np.where(used, weights, 0.0) * mesh.lumped_masses(density_kg_m3)[:, None]
    share = mass_shares(sources, claims, used, state.masses_kg, min_node_mass_fraction)
    masses = (share * state.masses_kg[sources]).sum(axis=1)
    masses *= state.masses_kg.sum() / masses.sum()
    fixed_old = np.zeros(old_count, dtype=bool)
    fixed_old[state.fixed_nodes] = True
    fixed = used.any(axis=1) & (fixed_old[sources] | ~used).all(axis=1)
    return mesh, NodeState(np.einsum("ks,ksj->kj", weights, state.positions[sources]),
                           np.einsum("ks,ksj->kj", weights, state.velocities[sources]),
                           np.einsum("ks,ksj->kj", share, state.external_forces_n[sources]),
                           masses, np.flatnonzero(fixed))


def mass_shares(sources: np.ndarray, claims: np.ndarray, used: np.ndarray, masses_kg: np.ndarray,
                min_node_mass_fraction: float) -> np.ndarray:
    """(N', S) fraction of each source's mass each new node gets: its claim (weight × lumped mass) over
    all claims on that source, first raised to φ_i = min(min_node_mass_fraction·mean mass / m_i, 1/n_i)
    (n_i: nodes drawing on i), then renormalised, so a copy keeps at least φ_i/2 of m_i."""
    old_count = len(masses_kg)
    total = np.bincount(sources[used], claims[used], old_count)
    count = np.bincount(sources[used], minlength=old_count)
    floor = np.minimum(min_node_mass_fraction * masses_kg.mean() / masses_kg, 1.0 / np.maximum(count, 1))
    share = np.where(used, np.maximum(claims / np.where(total > 0.0, total, 1.0)[sources], floor[sources]), 0.0)
    norm = np.bincount(sources[used], share[used], old_count)
    return np.where(used, share / np.where(norm > 0.0, norm, 1.0)[sources], 0.0)


def interior_face_pairs(tets: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interior faces as (slot_a, slot_b, key): slot = 4·tet + local face (TET_FACES), slot_a < slot_b."""
    keys = face_keys(tets[:, TET_FACES].reshape(-1, 3), n)
    order, start, count = key_groups(keys)
    first = start[count == 2]
    return order[first], order[first + 1], keys[order[first]]


@numba.njit(cache=True)
def _find(root, c):
    """The root of corner c in the union-find forest `root` (path halving)."""
    while root[c] != c:
        root[c] = root[root[c]]
        c = root[c]
    return c


@numba.njit(cache=True)
def _renumber_corners(tets, slot_a, slot_b, n):
    """(new tets, parent (N',)) when the corners (4·tet + local index) on each face pair slot_a[k], slot_b[k]
    are joined to the corners of the other tet holding the same nodes.

    Corners joined (transitively) form a component; the component holding a node's lowest corner keeps
    the node, each other one gets a new node n, n + 1, … in order of (old node, lowest corner)."""
    corner_node = tets.ravel()
    root = np.arange(len(corner_node))
    for k in range(len(slot_a)):  # union by lowest corner: a root is its component's lowest corner
        ta, tb = slot_a[k] // 4, slot_b[k] // 4
        for local in TET_FACES[slot_a[k] % 4]:
            ca = 4 * ta + local
            cb = 4 * tb
            while corner_node[cb] != corner_node[ca]:
                cb += 1
            ra, rb = _find(root, ca), _find(root, cb)
            if ra < rb:
                root[rb] = ra
            elif rb < ra:
                root[ra] = rb
    copies = np.zeros(n, dtype=np.int64)  # components per node beyond the first
    for c in range(len(root)):
        if root[c] == c:
            copies[corner_node[c]] += 1
    copies = np.maximum(copies - 1, 0)
    next_id = n + np.cumsum(copies) - copies
    parent = np.concatenate((np.arange(n), np.empty(copies.sum(), dtype=np.int64)))
    new_id = np.empty(len(root), dtype=np.int64)
    kept = np.zeros(n, dtype=np.bool_)
    for c in range(len(root)):
        node = corner_node[c]
        if root[c] != c:  # root[c] < c lies in the same component: its new node is known
            new_id[c] = new_id[root[c]]
        elif not kept[node]:
            kept[node] = True
            new_id[c] = node
        else:
            new_id[c] = next_id[node]
            parent[next_id[node]] = node
            next_id[node] += 1
    return new_id.reshape(-1, 4), parent


def _overshared_edges(skin: np.ndarray) -> np.ndarray:
    """Edges (E, 2), sorted pairs, that lie on more than two of the triangles `skin` (K, 3)."""
    n = int(skin.max()) + 1 if len(skin) else 1
    keys = edge_keys(skin[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), n)
    order, start, count = key_groups(keys)
    bad = keys[order[start[count > 2]]]
    return np.stack([bad // n, bad % n], axis=1)


def _still_shared(new_tets: np.ndarray, node_count: int, slot_a: np.ndarray, slot_b: np.ndarray) -> np.ndarray:
    """Mask over the face pairs (slot_a, slot_b) of the old tets: the two faces are still one in `new_tets`."""
    faces = new_tets[:, TET_FACES].reshape(-1, 3)
    return face_keys(faces[slot_a], node_count) == face_keys(faces[slot_b], node_count)


def split_skin_slots(tet_count: int, slot_a: np.ndarray, slot_b: np.ndarray, shared: np.ndarray) -> np.ndarray:
    """The skin's face slots, increasing, when of the interior face pairs (slot_a, slot_b) of the old tets
    those marked `shared` still are (all other faces of the tets lie on the skin)."""
    on_skin = np.ones(4 * tet_count, dtype=bool)
    on_skin[slot_a[shared]] = False
    on_skin[slot_b[shared]] = False
    return np.flatnonzero(on_skin)


def separate_faces(tets: np.ndarray, cut_faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(new_tets (M,4), parent (N'), opened): nodes duplicated so that the two tets of each cut face no longer
    share that face; parent[k] = the old node new node k copies (identity for k < N = tets.max()+1, copies
    appended); opened: how many faces no longer are shared.

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
    slot_a, slot_b, keys = interior_face_pairs(tets, n)
    new_tets, parent, shared = separate_pairs(tets, n, slot_a, slot_b, _cut_mask(keys, cut_faces, n))
    return new_tets, parent, int((~shared).sum())


def _cut_mask(keys: np.ndarray, cut_faces: np.ndarray, n: int) -> np.ndarray:
    """Mask over the face keys `keys`: the face is one of cut_faces (F, 3) (node triples, nodes < n)."""
    cut_faces = np.asarray(cut_faces, dtype=np.int64).reshape(-1, 3)
    if not len(cut_faces):
        return np.zeros(len(keys), dtype=bool)
    valid = (cut_faces.min(axis=1) >= 0) & (cut_faces.max(axis=1) < n)
    return isin_keys(keys, face_keys(cut_faces[valid], n))


def separate_pairs(tets: np.ndarray, n: int, slot_a: np.ndarray, slot_b: np.ndarray,
                   cut: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """separate_faces on the interior face pairs of `tets` (all of them: interior_face_pairs) whose
    mask `cut` is set (changed in place where the manifold fix closes faces); returns (new_tets, parent,
    mask over the pairs: still sharing their face)."""
    while True:
        new_tets, parent = _renumber_corners(tets, slot_a[~cut], slot_b[~cut], n)
        if not cut.any():
            return new_tets, parent, np.ones(len(cut), dtype=bool)
        shared = _still_shared(new_tets, len(parent), slot_a, slot_b)
        skin = new_tets[:, TET_FACES].reshape(-1, 3)[split_skin_slots(len(tets), slot_a, slot_b, shared)]
        bad = np.sort(parent[_overshared_edges(skin)], axis=1)
        if not len(bad):
            return new_tets, parent, shared
        open_ids = np.flatnonzero(cut)
        face_nodes = np.take_along_axis(tets[slot_a[open_ids] // 4], TET_FACES[slot_a[open_ids] % 4], axis=1)
        face_edges = edge_keys(face_nodes[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 3, 2), n)  # (F, 3) per cut face
        bad_keys = np.unique(edge_keys(bad, n))
        touches = isin_keys(face_edges, bad_keys).sum(axis=1)
        closed = False
        for key in bad_keys:
            around = np.flatnonzero((face_edges == key).any(axis=1))
            if len(around) and cut[open_ids[around]].all():
                choice = around[np.lexsort((slot_a[open_ids[around]], -touches[around]))[0]]
                cut[open_ids[choice]] = False
                closed = True
        if not closed:  # no cut face to close around an over-shared edge: open nothing
            cut[:] = False
