"""SurfaceSignedDistance (signed_distance.py): the exact signed distance to a closed, outward-wound surface."""
import numpy as np
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
