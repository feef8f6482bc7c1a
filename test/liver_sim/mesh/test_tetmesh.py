"""TetMesh (tetmesh.py): validation, orientation and the quantities derived from the tets."""
import numpy as np

from liver_sim.mesh.tetmesh import TetMesh, signed_volumes

from meshes import inverted_cube_arrays


def test_the_volumes_of_reoriented_tets_are_the_inputs_volumes_exactly():
    points, tets = inverted_cube_arrays()
    mesh = TetMesh.from_arrays(points, tets)
    np.testing.assert_array_equal(mesh.volumes, np.abs(signed_volumes(points, tets)))
