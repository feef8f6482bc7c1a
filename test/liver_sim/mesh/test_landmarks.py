"""Landmarks (landmarks.py) on a known shape: a 15 × 15 × 5 cm box whose top skin is raised by 1 cm at one node, so
the highest point, and the height of the upper skin anywhere above it, are known by hand."""
import numpy as np
import pytest

from liver_sim.mesh.landmarks import press_anchor, upper_skin_path, upper_skin_point
from liver_sim.mesh.tetmesh import TetMesh

from meshes import box_mesh

STEP = 0.05  # m: the box is 3 × 3 × 1 cubes of this side
RAISED = np.array([STEP, STEP, STEP + 0.01])  # the top node at (1, 1) of the grid, lifted by 1 cm


@pytest.fixture(scope="module")
def peaked():
    box = box_mesh(3, 3, 1, STEP)
    points = box.points.copy()
    top = np.flatnonzero(np.all(np.isclose(points, [STEP, STEP, STEP]), axis=1))
    assert len(top) == 1
    points[top[0]] = RAISED
    return TetMesh.from_arrays(points, box.tets, "peaked box")


def test_the_press_anchor_is_the_highest_skin_node_and_a_copy(peaked):
    anchor = press_anchor(peaked)
    np.testing.assert_array_equal(anchor, RAISED)
    anchor[2] = 1.0
    assert peaked.points[:, 2].max() == pytest.approx(RAISED[2])


@pytest.mark.parametrize("xy, height", [
    ((STEP, STEP), RAISED[2]),  # at the raised node
    ((1.5 * STEP, STEP), STEP + 0.005),  # half-way along a grid edge from it: the skin is flat between nodes
    ((2.5 * STEP, 2.5 * STEP), STEP),  # a square away from it: the flat top, not the bottom at z = 0
    ((0.0, 3 * STEP), STEP),  # a corner of the top
])
def test_the_upper_skin_point_is_on_the_top_above_the_point(peaked, xy, height):
    point = upper_skin_point(peaked, xy)
    np.testing.assert_allclose(point, [*xy, height], atol=1e-12)


def test_a_path_is_a_straight_line_dropped_onto_the_upper_skin(peaked):
    path = upper_skin_path(peaked, (0.0, STEP), (2 * STEP, STEP), points=5)  # over the raised node, along y = STEP
    np.testing.assert_allclose(path[:, 0], [0.0, 0.5 * STEP, STEP, 1.5 * STEP, 2 * STEP], atol=1e-12)
    np.testing.assert_allclose(path[:, 1], STEP, atol=1e-12)
    np.testing.assert_allclose(path[:, 2], [STEP, STEP + 0.005, STEP + 0.01, STEP + 0.005, STEP], atol=1e-12)


def test_a_point_beside_the_mesh_is_refused_naming_it(peaked):
    with pytest.raises(ValueError, match=r"the path point \[0\.2, 0\.05\] \(m\) is not above the mesh"):
        upper_skin_point(peaked, (0.2, 0.05))
    with pytest.raises(ValueError, match=r"the path point \[-0\.05, 0\.05\] \(m\)"):
        upper_skin_path(peaked, (0.1, 0.05), (-0.05, 0.05), points=4)
