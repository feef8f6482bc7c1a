"""TetMesh (tetmesh.py): validation, orientation and the quantities derived from the tets."""
import hashlib

import numpy as np
import pytest

from liver_sim.mesh.tetmesh import (
    TET_EDGES,
    TET_FACES,
    MeshError,
    TetMesh,
    face_keys,
    isin_keys,
    key_groups,
    signed_volumes,
    skin_slots,
    sorted_unique,
    unique_edges,
)

from meshes import CUBE_EDGE_M, cube_arrays, inverted_cube_arrays


def test_the_volumes_of_reoriented_tets_are_the_inputs_volumes_exactly():
    points, tets = inverted_cube_arrays()
    mesh = TetMesh.from_arrays(points, tets)
    np.testing.assert_array_equal(mesh.volumes, np.abs(signed_volumes(points, tets)))


#: The corner tet: the origin and the three unit points along the axes, 0.1 m long; positively oriented.
CORNER_POINTS = 0.1 * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def refused(points, tets, source="case.msh"):
    with pytest.raises(MeshError) as caught:
        TetMesh.from_arrays(points, tets, source)
    assert str(caught.value).startswith(f"{source}: ") and caught.value.source == source
    return caught.value.defect


def test_malformed_arrays_are_refused_naming_the_source_and_the_defect():
    assert refused(CORNER_POINTS, np.zeros((0, 4))) == "empty mesh: no tetrahedra"
    assert refused(CORNER_POINTS[:, :2], [[0, 1, 2, 3]]) == "node array has shape (4, 2), expected (N, 3)"
    assert refused(CORNER_POINTS, [[0, 1, 2]]) == "tetrahedron array has shape (1, 3), expected (M, 4)"
    assert refused(CORNER_POINTS, [[0, 1, 2, 4]]) == "tetrahedron indices out of range 0..3"
    assert refused(CORNER_POINTS, [[0, 1, 2, -1]]) == "tetrahedron indices out of range 0..3"
    assert refused([["a", "b", "c"]] * 4, [[0, 1, 2, 3]]).startswith("arrays are not numeric")
    assert refused(CORNER_POINTS, [[0, 1, 2, 3], [0, 1, 1, 2]]) == ("1 degenerate tetrahedra with a repeated node, "
                                                                    "first is tet 1")


def test_a_face_shared_by_three_tets_is_refused():
    points = np.vstack([CORNER_POINTS, [[0.05, 0.05, -0.1]], [[0.02, 0.02, 0.2]]])
    tets = [[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]]  # face 0-1-2: above, below, above
    assert refused(points, tets) == ("1 faces shared by more than two tetrahedra (overlapping or non-manifold "
                                     "elements)")


def test_unused_nodes_are_dropped_even_when_not_finite():
    points = np.vstack([[[np.nan, 0.0, 0.0]], CORNER_POINTS, [[1.0, 1.0, 1.0]]])  # nodes 0 and 5 unused
    mesh = TetMesh.from_arrays(points, [[1, 2, 3, 4]])
    np.testing.assert_array_equal(mesh.points, CORNER_POINTS)
    np.testing.assert_array_equal(mesh.tets, [[0, 1, 2, 3]])
    assert refused(points, [[0, 2, 3, 4]]) == "1 node(s) with NaN or infinite coordinates, first at node 0"


def test_the_corner_tet_volume_masses_and_dihedral_angles_by_hand():
    mesh = TetMesh.from_arrays(CORNER_POINTS, [[0, 2, 1, 3]])  # inverted as written: reoriented
    assert signed_volumes(mesh.points, mesh.tets)[0] > 0
    assert mesh.volume == pytest.approx(0.1 ** 3 / 6)
    np.testing.assert_allclose(mesh.lumped_masses(1000.0), [1000.0 * 0.1 ** 3 / 24] * 4)
    # edges along the axes meet at right angles; the others where the slanted face meets an axis plane,
    # whose normals (1, 1, 1)/√3 and an axis make arccos(1/√3)
    angles = np.sort(mesh.dihedral_angles_deg[0])
    np.testing.assert_allclose(angles, [np.degrees(np.arccos(1 / np.sqrt(3)))] * 3 + [90.0] * 3)


def test_a_regular_tets_six_dihedral_angles_are_arccos_one_third():
    points = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float) * 0.05
    mesh = TetMesh.from_arrays(points, [[0, 1, 2, 3]])
    np.testing.assert_allclose(mesh.dihedral_angles_deg, np.full((1, 6), np.degrees(np.arccos(1 / 3))))


def test_the_cubes_skin_is_its_twelve_outward_triangles():
    mesh = TetMesh.from_arrays(*cube_arrays())
    corners = mesh.points[mesh.skin]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    outward = corners.mean(axis=1) - CUBE_EDGE_M / 2
    assert len(mesh.skin) == 12 and (np.einsum("ij,ij->i", normals, outward) > 0).all()
    # every skin triangle lies in a face of the cube: one coordinate is 0 or the edge for all three corners
    assert all(((np.ptp(c, axis=0) == 0) & np.isin(c[0], [0.0, CUBE_EDGE_M])).any() for c in corners)
    np.testing.assert_array_equal(mesh.skin_nodes, np.arange(8))
    assert len(mesh.skin_edges) == 12 + 6  # the cube's edges and one diagonal per face
    assert len(mesh.edges) == 12 + 6 + 1  # and the main diagonal inside
    keys = np.sort(mesh.skin, axis=1).tolist()
    assert keys == sorted(keys)  # sorted by sorted node triple
    assert mesh.watertight
    slots = skin_slots(mesh.tets, len(mesh.points))
    np.testing.assert_array_equal(mesh.tets[slots // 4][np.arange(12)[:, None], TET_FACES[slots % 4]], mesh.skin)


def test_two_tets_sharing_only_an_edge_are_not_watertight():
    points = np.vstack([CORNER_POINTS, [[-0.1, 0.0, 0.0]], [[0.0, -0.1, 0.0]]])
    mesh = TetMesh.from_arrays(points, [[0, 1, 2, 3], [0, 3, 4, 5]])  # they share the edge 0-3 only
    assert len(mesh.skin) == 8
    assert not mesh.watertight


def test_the_summary_and_the_hash_of_the_cube():
    points, tets = cube_arrays()
    mesh = TetMesh.from_arrays(points, tets, source="cube")
    summary = mesh.summary()
    assert {k: summary[k] for k in ("source", "nodes", "tetrahedra", "skin_triangles", "watertight")} == {
        "source": "cube", "nodes": 8, "tetrahedra": 6, "skin_triangles": 12, "watertight": True}
    assert summary["volume_m3"] == pytest.approx(CUBE_EDGE_M ** 3)
    assert summary["bounds_m"] == [[0.0] * 3, [CUBE_EDGE_M] * 3] and summary["size_m"] == [CUBE_EDGE_M] * 3
    # each tet is a Kuhn simplex, a path along three cube edges: dihedral angles 45°, 60° and 90° (three)
    assert summary["min_dihedral_deg"] == pytest.approx(45.0) and summary["max_dihedral_deg"] == pytest.approx(90.0)
    assert np.sort(mesh.dihedral_angles_deg, axis=1) == pytest.approx(np.tile([45.0, 45.0, 60.0, 90, 90, 90], (6, 1)))
    # the hash is of the little-endian float64 nodes then the int64 tets, whatever the input types and source
    expected = hashlib.sha256(points.astype("<f8").tobytes() + mesh.tets.astype("<i8").tobytes()).hexdigest()
    assert summary["sha256"] == expected
    assert TetMesh.from_arrays(points.tolist(), tets.astype(np.int32), "other").sha256 == expected
    moved = points.copy()
    moved[7, 2] += 1e-9
    assert TetMesh.from_arrays(moved, tets).sha256 != expected


def test_key_helpers_agree_with_numpys_unique_and_isin():
    rng = np.random.default_rng(11)
    cells = rng.integers(0, 30, size=(200, 4))
    pairs = np.sort(cells[:, TET_EDGES].reshape(-1, 2), axis=1)
    np.testing.assert_array_equal(unique_edges(cells, TET_EDGES), np.unique(pairs, axis=0))
    triples = rng.permuted(rng.integers(0, 30, size=(300, 3)), axis=1)
    ordered = np.sort(triples, axis=1)
    lexicographic = ordered[np.lexsort(ordered.T[::-1])]
    np.testing.assert_array_equal(ordered[np.argsort(face_keys(triples, 30), kind="stable")], lexicographic)
    assert len(np.unique(face_keys(triples, 30))) == len(np.unique(ordered, axis=0))
    keys = rng.integers(-50, 50, size=400)
    np.testing.assert_array_equal(sorted_unique(keys), np.unique(keys))
    table = rng.integers(-50, 50, size=40)
    np.testing.assert_array_equal(isin_keys(keys, table), np.isin(keys, table))
    assert not isin_keys(keys, np.array([], dtype=np.int64)).any()
    order, start, count = key_groups(keys)
    values, counts = np.unique(keys, return_counts=True)
    np.testing.assert_array_equal(keys[order[start]], values)
    np.testing.assert_array_equal(count, counts)
    for g in range(len(values)):
        members = order[start[g]:start[g] + count[g]]
        np.testing.assert_array_equal(members, np.flatnonzero(keys == values[g]))  # in index order
