"""Validated tetrahedral meshes: the geometric component of the model (paper §2.1; P1 of docs/paper.md).

A :class:`TetMesh` holds node positions in metres and positively oriented
tetrahedra.  The skin (Glisson's capsule) is always derived from the tets: it is
the set of faces that belong to exactly one tetrahedron, oriented outward.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

# Faces of a positively oriented tet (a, b, c, d), each listed so that its
# right-hand normal points away from the opposite vertex.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
TRIANGLE_EDGES = np.array([[0, 1], [1, 2], [2, 0]], dtype=np.int64)

#: A tet whose volume is below this fraction of (mean edge length)^3 is degenerate.
DEGENERATE_RELATIVE_VOLUME = 1e-9


class MeshError(ValueError):
    """A mesh refused for a stated defect; the message names the source and the defect."""

    def __init__(self, source: str, defect: str):
        super().__init__(f"{source}: {defect}")
        self.source = source
        self.defect = defect


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed tet volumes (m^3): det[b-a, c-a, d-a] / 6, positive for positive orientation."""
    a = points[tets[:, 0]]
    return np.einsum(
        "ij,ij->i",
        points[tets[:, 1]] - a,
        np.cross(points[tets[:, 2]] - a, points[tets[:, 3]] - a),
    ) / 6.0


def dihedral_angles_deg(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The six interior dihedral angles (degrees) of each tet, shape (M, 6), in TET_EDGES order."""
    corners = points[tets]  # (M, 4, 3)
    face_pts = corners[:, TET_FACES]  # (M, 4, 3, 3)
    normals = np.cross(face_pts[:, :, 1] - face_pts[:, :, 0], face_pts[:, :, 2] - face_pts[:, :, 0])
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    # Edge (i, j) is shared by the faces opposite the two other vertices k, l.
    others = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]])
    cosines = np.einsum("mij,mij->mi", normals[:, others[:, 0]], normals[:, others[:, 1]])
    return 180.0 - np.degrees(np.arccos(np.clip(cosines, -1.0, 1.0)))


def edge_keys(ends: np.ndarray, node_count: int) -> np.ndarray:
    """One int64 key per undirected edge (..., 2), increasing with its sorted pair (nodes < node_count)."""
    return np.minimum(ends[..., 0], ends[..., 1]) * node_count + np.maximum(ends[..., 0], ends[..., 1])


def unique_edges(cells: np.ndarray, local_edges: np.ndarray) -> np.ndarray:
    """Sorted unique undirected edges (E, 2) of the given cells, in lexicographic order."""
    n = int(cells.max()) + 1 if cells.size else 1
    keys = sorted_unique(edge_keys(cells[:, local_edges], n).ravel())  # far faster than np.unique(axis=0)
    return np.stack([keys // n, keys % n], axis=1)


def face_keys(faces: np.ndarray, node_count: int) -> np.ndarray:
    """One int64 key per unordered node triple (F, 3), increasing with the sorted triple (nodes < node_count)."""
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    low = np.minimum(np.minimum(a, b), c)
    high = np.maximum(np.maximum(a, b), c)
    return (low * node_count + (a + b + c - low - high)) * node_count + high


def sorted_unique(keys: np.ndarray) -> np.ndarray:
    """np.unique of an int array (sorted distinct values), by a stable sort (faster on int64)."""
    ordered = np.sort(keys, kind="stable")
    return ordered[np.concatenate([[True], ordered[1:] != ordered[:-1]])] if len(ordered) else ordered


def key_groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(order, start, count): order = stable argsort of keys; the g-th distinct key (increasing) is held
    by the entries order[start[g] : start[g] + count[g]], in index order."""
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    start = np.flatnonzero(np.concatenate([[True], ordered[1:] != ordered[:-1]])) if len(keys) else order
    return order, start, np.diff(np.append(start, len(keys)))


def skin_slots(tets: np.ndarray, node_count: int) -> np.ndarray:
    """Slots (4·tet + local face, TET_FACES order) of the faces on exactly one tet, by increasing face key."""
    order, start, count = key_groups(face_keys(tets[:, TET_FACES].reshape(-1, 3), node_count))
    return order[start[count == 1]]


def isin_keys(keys: np.ndarray, table: np.ndarray) -> np.ndarray:
    """np.isin(keys, table) for int arrays, by binary search in the sorted table."""
    table = np.sort(table, kind="stable")
    if not len(table):
        return np.zeros(keys.shape, dtype=bool)
    return table[np.minimum(np.searchsorted(table, keys), len(table) - 1)] == keys


@dataclass(frozen=True, eq=False)
class TetMesh:
    """Nodes (N, 3) float64 in metres and tets (M, 4) int64, every tet positively oriented.

    Build one with :meth:`from_arrays`, which validates, drops unreferenced nodes
    and re-orients inverted tets, or refuses the input with a :class:`MeshError`.
    """

    points: np.ndarray
    tets: np.ndarray
    source: str = field(default="<memory>")

    @classmethod
    def from_arrays(cls, points, tets, source: str = "<memory>") -> "TetMesh":
        """Validate and normalise raw arrays; raise MeshError naming `source` and the defect."""
        try:
            points = np.ascontiguousarray(points, dtype=np.float64)
            tets = np.ascontiguousarray(tets, dtype=np.int64)
        except (TypeError, ValueError) as exc:
            raise MeshError(source, f"arrays are not numeric: {exc}") from None
        if tets.size == 0:
            raise MeshError(source, "empty mesh: no tetrahedra")
        if points.ndim != 2 or points.shape[1] != 3:
            raise MeshError(source, f"node array has shape {points.shape}, expected (N, 3)")
        if tets.ndim != 2 or tets.shape[1] != 4:
            raise MeshError(source, f"tetrahedron array has shape {tets.shape}, expected (M, 4)")
        if tets.min() < 0 or tets.max() >= len(points):
            raise MeshError(source, f"tetrahedron indices out of range 0..{len(points) - 1}")
        used = np.flatnonzero(np.bincount(tets.ravel(), minlength=len(points)))
        bad_nodes = ~np.isfinite(points[used]).all(axis=1)
        if bad_nodes.any():
            raise MeshError(source, f"{int(bad_nodes.sum())} node(s) with NaN or infinite coordinates, "
                                    f"first at node {int(used[np.argmax(bad_nodes)])}")
        if len(used) != len(points):  # drop nodes no tet uses (e.g. Gmsh geometry points)
            remap = np.full(len(points), -1, dtype=np.int64)
            remap[used] = np.arange(len(used))
            points, tets = points[used], remap[tets]
        repeated = (tets[:, TET_EDGES[:, 0]] == tets[:, TET_EDGES[:, 1]]).any(axis=1)
        if repeated.any():
            raise MeshError(source, f"{int(repeated.sum())} degenerate tetrahedra with a repeated node, "
                                    f"first is tet {int(np.argmax(repeated))}")
        volumes = signed_volumes(points, tets)
        edge_vec = points[tets[:, TET_EDGES[:, 1]]] - points[tets[:, TET_EDGES[:, 0]]]
        scale = float(np.sqrt(edge_vec[..., 0] ** 2 + edge_vec[..., 1] ** 2 + edge_vec[..., 2] ** 2).mean())
        flat = np.abs(volumes) <= DEGENERATE_RELATIVE_VOLUME * scale ** 3
        if flat.any():
            raise MeshError(source, f"{int(flat.sum())} degenerate (zero-volume) tetrahedra, "
                                    f"first is tet {int(np.argmax(flat))}")
        inverted = volumes < 0
        if inverted.any():
            tets = tets.copy()
            tets[inverted] = tets[inverted][:, [0, 1, 3, 2]]
        mesh = cls(points, tets, source)
        mesh._check_face_pairing()
        return mesh

    @cached_property
    def _face_groups(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(faces, order, start, count): the tets' faces (4·M, 3), TET_FACES order, grouped by node triple
        (key_groups of their face_keys)."""
        faces = self.tets[:, TET_FACES].reshape(-1, 3)
        return (faces, *key_groups(face_keys(faces, len(self.points))))

    def _check_face_pairing(self) -> None:
        """Every face is on one tet (skin) or two tets lying on opposite sides of it."""
        faces, order, start, count = self._face_groups
        if (count > 2).any():
            raise MeshError(self.source, f"{int((count > 2).sum())} faces shared by more than two "
                                         "tetrahedra (overlapping or non-manifold elements)")
        # Two positively oriented tets on opposite sides list a shared face with opposite
        # orientation, i.e. as an odd permutation of each other.
        parity = _permutation_parity(faces)
        first = start[count == 2]
        same_side = parity[order[first]] == parity[order[first + 1]]
        if same_side.any():
            raise MeshError(self.source, f"{int(same_side.sum())} interior faces with both tetrahedra on "
                                         "the same side: inverted or folded elements beyond repair")

    @cached_property
    def skin(self) -> np.ndarray:
        """Boundary triangles (K, 3), outward oriented, sorted by their sorted node triple for determinism."""
        faces, order, start, count = self._face_groups
        return faces[order[start[count == 1]]]

    @cached_property
    def volumes(self) -> np.ndarray:
        """Tet volumes (M,) in m^3, all positive (from_arrays orients every tet positively)."""
        return signed_volumes(self.points, self.tets)

    @property
    def volume(self) -> float:
        """Total volume in m^3."""
        return float(self.volumes.sum())

    @cached_property
    def edges(self) -> np.ndarray:
        """Unique tet edges (E, 2): the parenchyma springs' node pairs."""
        return unique_edges(self.tets, TET_EDGES)

    @cached_property
    def skin_edges(self) -> np.ndarray:
        """Unique skin-triangle edges: the capsule springs' node pairs."""
        return unique_edges(self.skin, TRIANGLE_EDGES)

    @cached_property
    def skin_nodes(self) -> np.ndarray:
        """Sorted indices of the nodes on the skin."""
        return np.flatnonzero(np.bincount(self.skin.ravel(), minlength=len(self.points)))

    @cached_property
    def dihedral_angles_deg(self) -> np.ndarray:
        """Interior dihedral angles (M, 6) in degrees."""
        return dihedral_angles_deg(self.points, self.tets)

    @cached_property
    def watertight(self) -> bool:
        """True when every skin edge joins exactly two skin triangles that traverse it oppositely."""
        directed = self.skin[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        forward = {tuple(e) for e in directed.tolist()}
        if len(forward) != len(directed):
            return False
        return all((b, a) in forward for a, b in forward)

    @property
    def bounds(self) -> np.ndarray:
        """[[xmin, ymin, zmin], [xmax, ymax, zmax]] in metres."""
        return np.array([self.points.min(axis=0), self.points.max(axis=0)])

    @cached_property
    def sha256(self) -> str:
        """Content hash of the little-endian float64 nodes and int64 tets."""
        digest = hashlib.sha256()
        digest.update(self.points.astype("<f8").tobytes())
        digest.update(self.tets.astype("<i8").tobytes())
        return digest.hexdigest()

    def lumped_masses(self, density_kg_m3: float) -> np.ndarray:
        """Node masses (N,) in kg: each tet's volume × density shared equally by its 4 nodes (P2)."""
        return np.bincount(self.tets.ravel(), np.repeat(self.volumes * density_kg_m3 / 4.0, 4), len(self.points))

    def summary(self) -> dict:
        """The figures `liver-sim mesh info` prints."""
        angles = self.dihedral_angles_deg
        return {
            "source": self.source,
            "nodes": int(len(self.points)),
            "tetrahedra": int(len(self.tets)),
            "skin_triangles": int(len(self.skin)),
            "volume_m3": self.volume,
            "bounds_m": self.bounds.tolist(),
            "size_m": (self.bounds[1] - self.bounds[0]).tolist(),
            "min_dihedral_deg": float(angles.min()),
            "max_dihedral_deg": float(angles.max()),
            "watertight": bool(self.watertight),
            "sha256": self.sha256,
        }


def _permutation_parity(faces: np.ndarray) -> np.ndarray:
    """0 where a face's vertex order is an even permutation of its sorted order, 1 where odd."""
    # For three distinct entries the parity is the number of inversions mod 2.
    inversions = (
        (faces[:, 0] > faces[:, 1]).astype(np.int64)
        + (faces[:, 0] > faces[:, 2])
        + (faces[:, 1] > faces[:, 2])
    )
    return inversions % 2
