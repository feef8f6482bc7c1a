"""Small tet meshes built in the tests themselves, and the checks that a mesh (or a model) is sound."""
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.csgraph

from liver_sim.mesh import TetMesh
from liver_sim.mesh.tetmesh import TET_FACES, signed_volumes

# Kuhn's split of a unit cube (corner index = 4·i + 2·j + k) into six tets.
KUHN_TETS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])


#: Side (m) of the cube of :func:`cube_arrays`.
CUBE_EDGE_M = 0.1


def cube_arrays():
    """A 0.1 m cube as 8 nodes and 6 positively oriented tets around its main diagonal (0-7)."""
    points = CUBE_EDGE_M * np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float)
    axis_orders = ([0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0])
    tets = np.array([np.cumsum([0] + [1 << axis for axis in axes]) for axes in axis_orders])
    negative = signed_volumes(points, tets) < 0
    tets[negative] = tets[negative][:, [0, 1, 3, 2]]
    return points, tets


def inverted_cube_arrays():
    """The cube with tet 0 written inverted (two nodes swapped)."""
    points, tets = cube_arrays()
    tets[0] = tets[0][[1, 0, 2, 3]]
    return points, tets


def box_mesh(nx: int, ny: int, nz: int, spacing_m: float) -> TetMesh:
    """A grid of nx × ny × nz cubes of side spacing_m, each cut into Kuhn's six tets."""
    grid = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij"), -1)
    points = grid.reshape(-1, 3) * spacing_m
    index = np.arange(len(points)).reshape(nx + 1, ny + 1, nz + 1)
    corners = np.stack([index[i:i + nx, j:j + ny, k:k + nz].ravel()
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)], axis=1)
    return TetMesh.from_arrays(points, corners[:, KUHN_TETS].reshape(-1, 4), source=f"box {nx}x{ny}x{nz}")


def kinetic_energy_j(model) -> float:
    """½·Σ m·|v|² (J) of a LiverModel."""
    return 0.5 * float((model.structure.masses_kg * (model.state.velocities ** 2).sum(axis=1)).sum())


def write_sphere_surface(path, radius, centre=(0.0, 0.0, 0.0), subdivisions=3):
    """A closed icosphere surface of `radius` about `centre`, in the file's units, written to `path` (by extension)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    sphere.apply_translation(centre)
    sphere.export(path)
    return path


def components(tets: np.ndarray, n: int) -> tuple[int, np.ndarray]:
    """(count, label per node) of the node graph joined through tet edges."""
    e = tets[:, [0, 1, 0, 2, 0, 3]].reshape(-1, 2)
    graph = scipy.sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return scipy.sparse.csgraph.connected_components(graph, directed=False)


def assert_sound(mesh: TetMesh) -> int:
    """No orphan node, no inverted tet, and every component's skin watertight (each edge on two
    triangles traversing it oppositely: a manifold at its edges) and outward; returns the number of
    components."""
    assert np.array_equal(np.unique(mesh.tets), np.arange(len(mesh.points)))
    assert (signed_volumes(mesh.points, mesh.tets) > 0).all()
    count, labels = components(mesh.tets, len(mesh.points))
    for label in range(count):
        piece = mesh.tets[labels[mesh.tets[:, 0]] == label]
        sub = TetMesh.from_arrays(mesh.points, piece)
        assert sub.watertight
        skin = sub.points[sub.skin]
        enclosed = np.einsum("ij,ij->i", skin[:, 0], np.cross(skin[:, 1], skin[:, 2])).sum() / 6.0
        assert enclosed == pytest.approx(sub.volume, rel=1e-9)
    return count


def model_state(model) -> dict:
    """Copies of all a topology change replaces in a LiverModel: node state, mesh, capsule, springs,
    masses, fixed and held nodes, substeps, stability bound, topology_version."""
    springs = model.structure.springs
    state, structure = model.state, model.structure
    arrays = (state.positions, state.velocities, state.external_forces_n, structure.masses_kg, state.inv_mass,
              structure.fixed_nodes, state.held_nodes, structure.mesh.points, structure.mesh.tets,
              structure.capsule_triangles, springs.node_i, springs.node_j, springs.rest_length_m)
    return {"arrays": [a.copy() for a in arrays], "substeps": model.structure.params.substeps,
            "stable_dt_s": model.structure.stable_dt_s, "topology_version": model.structure.version}


def fail_topology_changes(monkeypatch) -> list:
    """Make every topology change fail midway (build_springs raises after the node state was carried over) and
    record the model's state (model_state) as each change begins, into the list returned."""
    from liver_sim.physics import frame as frame_module
    from liver_sim.physics import structure as structure_module
    before = []
    apply = frame_module.apply_change

    def record_then_apply(structure, state, change):
        before.append(model_state(SimpleNamespace(structure=structure, state=state)))
        return apply(structure, state, change)

    def broken(*args, **kwargs):
        raise RuntimeError("injected")

    monkeypatch.setattr(frame_module, "apply_change", record_then_apply)
    monkeypatch.setattr(structure_module, "build_springs", broken)
    return before


def assert_same_state(state: dict, model) -> None:
    """The model holds `state` (model_state) still."""
    now = model_state(model)
    for a, b in zip(state.pop("arrays"), now.pop("arrays"), strict=True):
        np.testing.assert_array_equal(a, b)
    assert state == now


def perturbed_state(mesh: TetMesh, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(x, v) of `mesh` off rest: its points moved by 3 mm and velocities of 5 cm/s (normal draws, `seed`)."""
    rng = np.random.default_rng(seed)
    x = mesh.points + rng.normal(scale=0.003, size=mesh.points.shape)
    v = rng.normal(scale=0.05, size=mesh.points.shape)
    return x, v


def face_keys(faces) -> set:
    """The faces (F, 3) as a set of sorted node triples."""
    return {tuple(sorted(f)) for f in np.asarray(faces).tolist()}


def interior_faces(tets: np.ndarray) -> np.ndarray:
    """The faces (sorted node triples) that two of `tets` share."""
    faces = np.sort(tets[:, TET_FACES].reshape(-1, 3), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return unique[counts == 2]


def opened_faces(old_tets: np.ndarray, new_tets: np.ndarray, parent: np.ndarray) -> list:
    """Old interior faces whose two tets no longer share them after the change (`parent`: new node → old)."""
    still = face_keys(parent[interior_faces(new_tets)])
    return [f for f in face_keys(interior_faces(old_tets)) if f not in still]
