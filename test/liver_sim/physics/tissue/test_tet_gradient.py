"""The gradient of a nodal field over a tetrahedron (physics.tissue.tet_gradient): the affine map itself for an
affine field, and only the nodes it is told to count."""
import numba
import numpy as np

from liver_sim.physics.tissue.fem_kernels import build_tets
from liver_sim.physics.tissue.tet_gradient import EVERY_NODE, tet_gradient

from meshes import box_mesh

LINEAR = np.array([[1.1, 0.2, 0.0], [-0.1, 0.9, 0.3], [0.05, 0.0, 1.2]])


@numba.njit(cache=False)
def gradients(values, tets, g, counts):
    out = np.empty((tets.shape[0], 3, 3))
    for e in range(tets.shape[0]):
        t = tet_gradient(values, tets[e], g[e], counts)
        for r in range(9):
            out[e, r // 3, r % 3] = t[r]
    return out


def test_an_affine_field_has_the_affine_map_for_gradient_in_every_element():
    mesh = box_mesh(1, 1, 1, 0.01)
    law = build_tets(mesh.points, mesh.tets, 1.0, 0.3, 0.0)
    moved = mesh.points @ LINEAR.T + [0.01, 0.02, 0.03]
    deformation = gradients(moved, law.tets, law.gradients, EVERY_NODE)
    np.testing.assert_allclose(deformation, np.broadcast_to(LINEAR, deformation.shape), atol=1e-12)


def test_a_node_not_counted_leaves_out_its_term():
    mesh = box_mesh(1, 1, 1, 0.01)
    law = build_tets(mesh.points, mesh.tets, 1.0, 0.3, 0.0)
    moved = mesh.points @ LINEAR.T + [0.01, 0.02, 0.03]
    without = gradients(moved, law.tets, law.gradients, (True, False, True, True))
    second = moved[law.tets[:, 1]]
    expected = LINEAR - np.einsum("ti,tj->tij", second, law.gradients[:, 1])
    np.testing.assert_allclose(without, expected, atol=1e-12)
