"""Small tet meshes built in the tests themselves."""
import numpy as np

from liver_sim.mesh import TetMesh

# Kuhn's split of a unit cube (corner index = 4·i + 2·j + k) into six tets.
KUHN_TETS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])


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
    return 0.5 * float((model.masses_kg * (model.velocities ** 2).sum(axis=1)).sum())


def write_sphere_surface(path, radius, centre=(0.0, 0.0, 0.0), subdivisions=3):
    """A closed icosphere surface of `radius` about `centre`, in the file's units, written to `path` (by extension)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    sphere.apply_translation(centre)
    sphere.export(path)
    return path
