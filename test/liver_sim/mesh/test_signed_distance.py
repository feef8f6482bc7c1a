"""SurfaceSignedDistance (signed_distance.py): the exact signed distance to a closed, outward-wound surface."""
import numpy as np
import pytest
import trimesh

from liver_sim.mesh.signed_distance import SurfaceSignedDistance

SPHERE_RADIUS = 0.05  # m


def test_signed_distance_to_a_sphere_surface():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=SPHERE_RADIUS)
    distance = SurfaceSignedDistance(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    rng = np.random.default_rng(1)
    directions = rng.normal(size=(500, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = rng.uniform(0.0, 3 * SPHERE_RADIUS, size=500)
    values = distance(directions * radii[:, None])
    np.testing.assert_allclose(values, radii - SPHERE_RADIUS, atol=SPHERE_RADIUS * 2e-3)
    assert distance(np.zeros((2, 2, 3))).shape == (2, 2)


def box_distance(points, half):
    """The exact signed distance (m) to the box |x| <= half, negative inside."""
    q = np.abs(points) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


HALF = np.array([0.03, 0.02, 0.05])  # m


@pytest.fixture(scope="module")
def box():
    surface = trimesh.creation.box(extents=2 * HALF)  # 12 triangles, wound outward
    return SurfaceSignedDistance(np.asarray(surface.vertices), np.asarray(surface.faces))


def test_a_box_is_exact_at_faces_edges_and_corners_inside_and_out(box):
    """Most random points of a box twice the size are nearest a corner or an edge: their signs come from the
    vertex and edge pseudonormals, their magnitudes from the nearest feature."""
    points = np.random.default_rng(5).uniform(-2 * HALF, 2 * HALF, size=(3000, 3))
    np.testing.assert_allclose(box(points), box_distance(points, HALF), rtol=0, atol=1e-12)
    corner = HALF + 0.01  # outside, nearest the corner: |(0.01, 0.01, 0.01)|
    assert box(corner[None])[0] == pytest.approx(0.01 * np.sqrt(3), abs=1e-12)
    assert box(np.array([[0.0, 0.0, 0.0], HALF - 0.001]))[0] == pytest.approx(-0.02, abs=1e-12)
    assert box((HALF - 0.001)[None])[0] == pytest.approx(-0.001, abs=1e-12)


def test_reversed_winding_turns_the_sign():
    surface = trimesh.creation.box(extents=2 * HALF)
    points = np.random.default_rng(6).uniform(-2 * HALF, 2 * HALF, size=(500, 3))
    inward = SurfaceSignedDistance(np.asarray(surface.vertices), np.asarray(surface.faces)[:, ::-1])
    np.testing.assert_allclose(inward(points), -box_distance(points, HALF), rtol=0, atol=1e-12)


def test_a_torus_is_outside_in_its_hole_and_within_its_facets_of_the_exact_distance():
    """Non-convex: the hole's centre is outside, at R - r. The facets lie within their sagittas of the torus."""
    major, minor, around, across = 0.035, 0.015, 96, 48
    surface = trimesh.creation.torus(major_radius=major, minor_radius=minor, major_sections=around,
                                     minor_sections=across)
    distance = SurfaceSignedDistance(np.asarray(surface.vertices), np.asarray(surface.faces))
    sagittas = (major + minor) * (1 - np.cos(np.pi / around)) + minor * (1 - np.cos(np.pi / across))
    points = np.random.default_rng(7).uniform(-0.06, 0.06, size=(3000, 3))
    exact = np.hypot(np.hypot(points[:, 0], points[:, 1]) - major, points[:, 2]) - minor
    np.testing.assert_allclose(distance(points), exact, rtol=0, atol=sagittas)
    assert distance(np.zeros(3)) == pytest.approx(major - minor, abs=sagittas)
    assert distance(np.array([major, 0.0, 0.0])) == pytest.approx(-minor, abs=sagittas)
