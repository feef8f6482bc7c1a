"""What a topology change hands the model (physics.topology.change): faces opened by node duplication with the skin
kept manifold, a change checked before it is applied, the node state and masses carried onto the new nodes."""
import numpy as np
import pytest
from pulls import SPACING_M, pulled_bar

from liver_sim.mesh.liver_shape import default_liver
from liver_sim.mesh.tetmesh import TET_FACES, TetMesh
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.topology.change import (
    NodeState,
    TopologyChange,
    carry_over,
    check_change,
    mass_shares,
    separate_faces,
)
from liver_sim.physics.topology.tearing import duplication_change

from meshes import assert_sound, box_mesh, components, face_keys, interior_faces, opened_faces

#: Two tets sharing the face (0, 1, 2), node 3 above it and node 4 below.
TWO_TETS = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, 0.3, -1.0]], dtype=float),
            np.array([[0, 1, 2, 3], [0, 2, 1, 4]]))


# --- separate_faces -----------------------------------------------------------------------------

def test_one_face_cut_between_two_tets():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, 0.3, -1.0]])
    mesh = TetMesh.from_arrays(points, [[0, 1, 2, 3], [0, 2, 1, 4]])
    tets, parent, _ = separate_faces(mesh.tets, [[2, 0, 1]])
    assert np.array_equal(parent[:5], np.arange(5))
    assert sorted(parent[5:].tolist()) == [0, 1, 2]
    assert not set(tets[0].tolist()) & set(tets[1].tolist())
    torn = TetMesh.from_arrays(mesh.points[parent], tets)
    assert len(torn.points) == len(parent) and len(torn.skin) == 8
    assert_sound(torn)


def test_non_interior_faces_are_ignored():
    mesh = box_mesh(2, 2, 2, 0.01)
    tets, parent, _ = separate_faces(mesh.tets, mesh.skin[:5])
    assert np.array_equal(tets, mesh.tets) and np.array_equal(parent, np.arange(len(mesh.points)))


def test_crack_ending_inside_keeps_the_skin_manifold():
    mesh = box_mesh(4, 4, 4, 0.01)
    faces = mesh.tets[:, TET_FACES].reshape(-1, 3)
    corners = mesh.points[faces]
    on_plane = np.isclose(corners[:, :, 0], 0.02).all(axis=1)
    crack = faces[on_plane & (corners[:, :, 1] <= 0.02 + 1e-9).all(axis=1)]  # half the plane
    tets, parent, _ = separate_faces(mesh.tets, crack)
    torn = TetMesh.from_arrays(mesh.points[parent], tets)
    assert len(torn.points) > len(mesh.points)
    assert opened_faces(mesh.tets, tets, parent)
    assert components(tets, len(parent))[0] == 1  # still one piece
    assert_sound(torn)


def test_random_cuts_keep_every_skin_edge_on_two_triangles():
    mesh = default_liver()
    faces = interior_faces(mesh.tets)
    rng = np.random.default_rng(3)
    for fraction in (0.05, 0.2, 0.5):
        cut = faces[rng.random(len(faces)) < fraction]
        tets, parent, _ = separate_faces(mesh.tets, cut)
        opened = opened_faces(mesh.tets, tets, parent)
        assert face_keys(opened) <= face_keys(cut)
        assert_sound(TetMesh.from_arrays(mesh.points[parent], tets))



# --- check_change and carry_over ----------------------------------------------------------------

def split_two_tets() -> tuple[TetMesh, TopologyChange]:
    """The two tets and the change that opens their shared face: three nodes duplicated, no capsule."""
    points, tets = TWO_TETS
    mesh = TetMesh.from_arrays(points, tets)
    new_tets, parent, opened = separate_faces(mesh.tets, [[0, 1, 2]])
    assert opened == 1 and len(parent) == 8
    return mesh, TopologyChange(points[parent], new_tets, np.zeros((0, 3), np.int64), parent[:, None],
                                np.ones((len(parent), 1)), opened)


def test_a_sound_change_is_checked_into_its_mesh():
    mesh, change = split_two_tets()
    new = check_change(change, len(mesh.points), "split")
    assert new.source == "split" and len(new.points) == 8 and len(new.skin) == 8
    identity = TopologyChange(mesh.points, mesh.tets, mesh.skin, np.arange(5)[:, None], np.ones((5, 1)), 0)
    np.testing.assert_array_equal(check_change(identity, 5).tets, mesh.tets)


@pytest.mark.parametrize("field, value, message", [
    ("node_sources", "out of range", "node_sources must index the old nodes 0..4"),
    ("node_sources", "short", "node_sources and node_weights must both be"),
    ("node_weights", "half", "node_weights must be finite, non-negative and sum to 1"),
    ("rest_points", "nan", "rest_points must be finite"),
    ("tets", "inverted", "positively oriented"),
    ("capsule_triangles", "not a face", "capsule_triangles must be skin triangles"),
])
def test_an_unsound_change_is_refused_by_field(field, value, message):
    mesh, change = split_two_tets()
    bad = {"out of range": lambda: np.where(change.node_sources == 4, 5, change.node_sources),
           "short": lambda: change.node_sources[:-1],
           "half": lambda: change.node_weights * 0.5,
           "nan": lambda: np.where(np.arange(8)[:, None] == 7, np.nan, change.rest_points),
           "inverted": lambda: change.tets[:, [1, 0, 2, 3]],
           "not a face": lambda: np.array([[0, 1, 4]])}[value]()
    fields = {f: getattr(change, f) for f in TopologyChange.__dataclass_fields__}
    with pytest.raises(ValueError, match=message):
        check_change(TopologyChange(**{**fields, field: bad}), len(mesh.points))


def test_carry_over_copies_the_duplicated_nodes_state_and_splits_mass_and_load():
    mesh, change = split_two_tets()
    rng = np.random.default_rng(0)
    state = NodeState(mesh.points + rng.normal(scale=0.01, size=(5, 3)), rng.normal(size=(5, 3)),
                      rng.normal(size=(5, 3)), np.array([1.0, 2.0, 3.0, 4.0, 5.0]), np.array([0]))
    new, carried = carry_over(change, state, "split", 1000.0, 0.0)
    parent = change.node_sources[:, 0]
    np.testing.assert_array_equal(carried.positions, state.positions[parent])
    np.testing.assert_array_equal(carried.velocities, state.velocities[parent])
    assert carried.masses_kg.sum() == pytest.approx(15.0)
    for old in range(5):  # each old node's mass is split among its copies, so momentum and load are kept too
        copies = parent == old
        assert carried.masses_kg[copies].sum() == pytest.approx(state.masses_kg[old])
        np.testing.assert_allclose(carried.external_forces_n[copies].sum(axis=0), state.external_forces_n[old])
    np.testing.assert_allclose((carried.masses_kg[:, None] * carried.velocities).sum(axis=0),
                               (state.masses_kg[:, None] * state.velocities).sum(axis=0))
    np.testing.assert_array_equal(carried.fixed_nodes, np.flatnonzero(parent == 0))  # node 0 and its copy
    assert len(carried.fixed_nodes) == 2 and len(new.points) == 8


def test_mass_shares_follow_the_claims_raised_to_the_floor():
    # node 0 claimed 1 : 3 by two new nodes, node 1 by one; masses 1 kg each (mean 1)
    sources, claims = np.array([[0], [0], [1]]), np.array([[1.0], [3.0], [2.0]])
    used, masses = np.ones((3, 1), bool), np.array([1.0, 1.0])
    np.testing.assert_allclose(mass_shares(sources, claims, used, masses, 0.0), [[0.25], [0.75], [1.0]])
    # floor min(1·1/1, 1/2) = 0.5 on node 0: (0.5, 0.75) renormalised to (0.4, 0.6)
    np.testing.assert_allclose(mass_shares(sources, claims, used, masses, 1.0), [[0.4], [0.6], [1.0]])


def test_momentum_and_mass_carry_over_a_duplication():
    model = pulled_bar(16.0)
    for _ in range(5):
        model.step_frame()
    model.state.velocities += np.random.default_rng(1).normal(0.0, 0.01, model.state.velocities.shape)
    model.state.velocities[model.structure.fixed_nodes] = 0.0
    mesh = model.structure.mesh
    faces = mesh.tets[:, TET_FACES].reshape(-1, 3)
    plane = np.isclose(mesh.points[faces][:, :, 0], 5 * SPACING_M).all(axis=1)
    change = duplication_change(mesh.points, mesh.tets, model.structure.capsule_triangles, faces[plane])
    momentum = (model.structure.masses_kg[:, None] * model.state.velocities).sum(axis=0)
    old_masses = model.structure.masses_kg.copy()
    mass, force = old_masses.sum(), model.state.external_forces_n.sum(axis=0)
    positions = model.state.positions.copy()
    model.apply(change)
    assert components(model.structure.mesh.tets, len(model.state.positions))[0] == 2
    assert model.structure.masses_kg.sum() == pytest.approx(mass, rel=1e-12)
    assert np.allclose((model.structure.masses_kg[:, None] * model.state.velocities).sum(axis=0), momentum,
                       rtol=1e-12, atol=1e-15)
    assert np.allclose(model.state.external_forces_n.sum(axis=0), force, rtol=1e-12)
    assert np.array_equal(model.state.positions, positions[change.node_sources[:, 0]])
    source = change.node_sources[:, 0]
    copies = np.bincount(source)[source]
    floor = 0.5 * np.minimum(model.structure.params.min_node_mass_fraction * old_masses.mean(),
                             old_masses[source] / copies)
    assert (model.structure.masses_kg >= floor * (1 - 1e-12)).all()
    assert model.structure.version == 1
    assert_sound(model.structure.mesh)
    model.reset()
    assert np.array_equal(model.state.positions, model.structure.mesh.points)
    for _ in range(100):
        assert model.step_frame().divergence is None



def test_copies_of_fixed_nodes_stay_fixed():
    mesh = box_mesh(2, 2, 2, 0.02)
    centre = int(np.argmin(np.linalg.norm(mesh.points - 0.02, axis=1)))
    model = LiverModel(mesh, ModelParams(fixed_nodes=(centre,)))
    faces = mesh.tets[:, TET_FACES].reshape(-1, 3)
    plane = np.isclose(mesh.points[faces][:, :, 0], 0.02).all(axis=1)
    change = duplication_change(mesh.points, mesh.tets, model.structure.capsule_triangles, faces[plane])
    model.apply(change)
    copies = np.flatnonzero(change.node_sources[:, 0] == centre)
    assert len(copies) == 2
    assert np.array_equal(model.structure.fixed_nodes, copies) and (model.state.inv_mass[copies] == 0.0).all()

