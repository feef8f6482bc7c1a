"""Isosurface stuffing (Labelle & Shewchuk 2007): volume, closed outward skin, angle bounds, determinism."""
import math

import numpy as np
import pytest

from liver_sim.mesh.stuffing import tetrahedralize_implicit, tetrahedralize_to_target

RADIUS = 0.05
LOWER, UPPER = np.array([-0.06, -0.06, -0.06]), np.array([0.065, 0.07, 0.06])
# The paper's guaranteed range for alpha_long = 0.24999, alpha_short = 0.41189.
PAPER_MIN_DIHEDRAL, PAPER_MAX_DIHEDRAL = 10.7, 164.8


def sphere(points):
    return np.linalg.norm(points, axis=1) - RADIUS


def ellipsoid(points, radii=np.array([0.05, 0.03, 0.02])):
    """Lower bound of the distance to an ellipsoid: (|p / r| - 1) min(r)."""
    return (np.linalg.norm(points / radii, axis=1) - 1.0) * radii.min()


def torus(points, major=0.035, minor=0.015):
    ring = np.hypot(points[:, 0], points[:, 1]) - major
    return np.hypot(ring, points[:, 2]) - minor


def rounded_box(points, half=np.array([0.04, 0.025, 0.03]), rounding=0.005):
    q = np.abs(points) - (half - rounding)
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0) - rounding


def outward_flux_volume(mesh):
    """Divergence theorem: V = sum over skin triangles of centroid . (area * unit normal) / 3."""
    tri = mesh.points[mesh.skin]
    doubled_area_normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return float(np.einsum("ij,ij->", tri.mean(axis=1), doubled_area_normals) / 6.0)


@pytest.fixture(scope="module")
def sphere_mesh():
    return tetrahedralize_implicit(sphere, LOWER, UPPER, 0.01, source="sphere")


def test_sphere_volume_close_to_exact(sphere_mesh):
    exact = 4.0 / 3.0 * math.pi * RADIUS ** 3
    assert sphere_mesh.volume == pytest.approx(exact, rel=0.03)


def test_sphere_skin_is_a_closed_outward_surface_on_the_isosurface(sphere_mesh):
    assert sphere_mesh.watertight
    assert outward_flux_volume(sphere_mesh) == pytest.approx(sphere_mesh.volume, rel=1e-9)
    # Euler characteristic of a sphere: V - E + F = 2.
    assert len(sphere_mesh.skin_nodes) - len(sphere_mesh.skin_edges) + len(sphere_mesh.skin) == 2
    # Every skin node is a cut point or a warped vertex, so it lies on f = 0; a
    # disagreement between neighbouring stencils would leave lattice faces in the skin.
    assert np.abs(sphere(sphere_mesh.points[sphere_mesh.skin_nodes])).max() < 1e-9


def test_sphere_dihedral_angles_within_the_paper_bound(sphere_mesh):
    angles = sphere_mesh.dihedral_angles_deg
    assert angles.min() >= PAPER_MIN_DIHEDRAL
    assert angles.max() <= PAPER_MAX_DIHEDRAL


@pytest.mark.parametrize("shape", [sphere, ellipsoid, torus, rounded_box])
@pytest.mark.parametrize("spacing, shift", [(0.0123, (0.0, 0.0, 0.0)), (0.0071, (0.0013, -0.0021, 0.0007)),
                                            (0.0052, (-0.0009, 0.0017, 0.0031))])
def test_stencils_keep_the_angle_bound_and_close_the_skin(shape, spacing, shift):
    """Many lattice placements relative to curved, flat and saddle-shaped surfaces hit every stencil."""
    mesh = tetrahedralize_implicit(lambda p: shape(p - np.array(shift)), LOWER, UPPER, spacing)
    angles = mesh.dihedral_angles_deg
    assert angles.min() >= PAPER_MIN_DIHEDRAL
    assert angles.max() <= PAPER_MAX_DIHEDRAL
    assert mesh.watertight
    assert outward_flux_volume(mesh) == pytest.approx(mesh.volume, rel=1e-9)
    assert np.abs(shape(mesh.points[mesh.skin_nodes] - np.array(shift))).max() < 1e-9


def test_same_inputs_give_identical_arrays():
    first = tetrahedralize_implicit(sphere, LOWER, UPPER, 0.0087)
    second = tetrahedralize_implicit(sphere, LOWER, UPPER, 0.0087)
    assert first.sha256 == second.sha256
    assert np.array_equal(first.points, second.points) and np.array_equal(first.tets, second.tets)


def test_lattice_is_anchored_to_the_lower_corner():
    """Moving `lower` by whole cubes keeps the lattice, hence the mesh; moving it off the lattice does not."""
    spacing = 0.0087
    base = tetrahedralize_implicit(sphere, LOWER, UPPER, spacing)
    whole = tetrahedralize_implicit(sphere, LOWER - [2 * spacing, spacing, 3 * spacing], UPPER, spacing)
    shifted = tetrahedralize_implicit(sphere, LOWER - [0.3 * spacing, 0.0, 0.0], UPPER, spacing)
    assert len(whole.tets) == len(base.tets)
    assert np.allclose(np.sort(whole.points, axis=0), np.sort(base.points, axis=0), atol=1e-12)
    assert shifted.sha256 != base.sha256
    interior = base.points[np.setdiff1d(np.arange(len(base.points)), base.skin_nodes)]
    shifted_interior = shifted.points[np.setdiff1d(np.arange(len(shifted.points)), shifted.skin_nodes)]
    assert not np.isclose(interior[:, 0, None], shifted_interior[None, :, 0], atol=1e-6).any()


@pytest.mark.parametrize("target", [400, 3000, 20000])
def test_target_tet_count_is_met_within_ten_percent(target):
    mesh = tetrahedralize_to_target(sphere, LOWER, UPPER, target)
    assert abs(len(mesh.tets) - target) <= 0.1 * target
    assert mesh.watertight


def test_target_search_is_deterministic():
    assert (tetrahedralize_to_target(torus, LOWER, UPPER, 2500).sha256
            == tetrahedralize_to_target(torus, LOWER, UPPER, 2500).sha256)


@pytest.mark.parametrize("call, message", [
    (lambda: tetrahedralize_implicit(sphere, LOWER, UPPER, -0.01), "spacing"),
    (lambda: tetrahedralize_implicit(sphere, UPPER, LOWER, 0.01), "invalid box"),
    (lambda: tetrahedralize_implicit(lambda p: np.ones(len(p)), LOWER, UPPER, 0.01), "no solid"),
    (lambda: tetrahedralize_implicit(lambda p: np.full(len(p), np.nan), LOWER, UPPER, 0.01), "NaN"),
    (lambda: tetrahedralize_to_target(sphere, LOWER, UPPER, 0), "positive"),
    (lambda: tetrahedralize_to_target(sphere, LOWER, UPPER, 1), "within 10 %"),
])
def test_unusable_arguments_are_refused_with_a_reason(call, message):
    with pytest.raises(ValueError, match=message):
        call()
