"""The indentation check's reference: linear P1 elasticity pressed by an ideal frictionless sphere."""
import numpy as np
import pytest

from liver_sim.studies.indentation import block_mesh, bonded_layer_factor, bottom_nodes, hertz_force_n
from liver_sim.studies.indentation_reference import sphere_indentation, stiffness_matrix

YOUNG_PA, POISSON, RADIUS_M, THICKNESS_M = 2000.0, 0.45, 0.015, 0.06


@pytest.fixture(scope="module")
def small_block():
    return block_mesh(3000)


def test_rigid_motions_cost_no_force_and_a_uniform_strain_its_textbook_energy(small_block):
    points = small_block.points
    stiffness = stiffness_matrix(small_block, YOUNG_PA, POISSON)
    translation = np.tile([1e-3, -2e-3, 5e-4], len(points))
    rotation = np.cross([0.0, 0.0, 1e-2], points).ravel()  # small rotation about z: linearised, in the null space
    assert np.abs(stiffness @ translation).max() < 1e-12
    assert np.abs(stiffness @ rotation).max() < 1e-9
    strain = np.array([[1e-2, 2e-3, 0.0], [2e-3, -4e-3, 1e-3], [0.0, 1e-3, 3e-3]])
    displacement = (points @ strain.T).ravel()
    lam = YOUNG_PA * POISSON / ((1 + POISSON) * (1 - 2 * POISSON))
    mu = YOUNG_PA / (2 * (1 + POISSON))
    corners = points[small_block.tets]
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])).sum() / 6.0
    expected = 0.5 * volume * (lam * np.trace(strain) ** 2 + 2 * mu * np.sum(strain * strain))
    assert 0.5 * displacement @ (stiffness @ displacement) == pytest.approx(expected, rel=1e-9)


def test_the_ideal_sphere_pushes_more_with_depth_and_holds_no_node_it_would_pull(small_block):
    rows = sphere_indentation(small_block, YOUNG_PA, POISSON, RADIUS_M, (0.002, 0.004, 0.006),
                              bottom_nodes(small_block))
    forces = [row["force_n"] for row in rows]
    assert 0.0 < forces[0] < forces[1] < forces[2]
    assert rows[0]["held_nodes"] <= rows[1]["held_nodes"] <= rows[2]["held_nodes"]


def test_the_reference_approaches_the_bonded_hertz_force_as_the_mesh_resolves_the_contact():
    def ratios(target_tets):
        mesh = block_mesh(target_tets)
        rows = sphere_indentation(mesh, YOUNG_PA, POISSON, RADIUS_M, (0.001, 0.005), bottom_nodes(mesh))
        return [row["force_n"] / (hertz_force_n(YOUNG_PA, POISSON, RADIUS_M, row["depth_m"])
                                  * bonded_layer_factor(POISSON, RADIUS_M, row["depth_m"], THICKNESS_M))
                for row in rows]
    coarse, fine = ratios(5000), ratios(20000)
    assert abs(fine[0] - 1.0) < abs(coarse[0] - 1.0)  # 1 mm: a contact radius of 3.9 mm, resolved better
    assert all(abs(r - 1.0) < 0.1 for r in (coarse[1], fine[1]))  # 5 mm: 8.7 mm, resolved on both
