"""The local model's closed-form penetration and force, the device map and the passivity bounds."""
import math

import numpy as np
import pytest

from haptic_bridge.rendering import ModelGlide, blend, contact_force, max_passive_stiffness, passivity_damping_min
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.geometry.rotations import quaternion_to_matrix
from liver_sim.base.local_model import LocalModel, penetration

PLANE = LocalModel.plane(point=[0.0, 0.0, 0.1], normal=[0.0, 0.0, 2.0])  # surface z = 0.1 m, outward +z
SPHERE = LocalModel.sphere(centre=[0.1, 0.0, 0.0], radius_m=0.05)


def test_plane_normal_is_normalised_and_the_model_is_immutable():
    model = LocalModel.plane(point=[1, 2, 3], normal=[3.0, 4.0, 0.0])
    np.testing.assert_allclose(model.normal, [0.6, 0.8, 0.0])
    with pytest.raises(ValueError):
        model.normal[0] = 1.0
    with pytest.raises(AttributeError):
        model.point = np.zeros(3)


@pytest.mark.parametrize("kwargs, field", [
    ({"point": [0, 0, 0], "normal": [0, 0, 0]}, "LocalModel.normal"),
    ({"point": [0, 0, 0], "normal": [0, np.nan, 1]}, "LocalModel.normal"),
    ({"point": [0, 0, np.inf], "normal": [0, 0, 1]}, "LocalModel.point"),
    ({"point": [0, 0], "normal": [0, 0, 1]}, "LocalModel.point"),
])
def test_plane_refuses_bad_fields_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        LocalModel.plane(**kwargs)


@pytest.mark.parametrize("kwargs, field", [
    ({"centre": [0, 0, 0], "radius_m": 0.0}, "LocalModel.radius_m"),
    ({"centre": [0, 0, 0], "radius_m": -0.1}, "LocalModel.radius_m"),
    ({"centre": [0, 0, 0], "radius_m": np.nan}, "LocalModel.radius_m"),
    ({"centre": [np.nan, 0, 0], "radius_m": 0.1}, "LocalModel.centre"),
])
def test_sphere_refuses_bad_fields_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        LocalModel.sphere(**kwargs)


@pytest.mark.parametrize("tip, tool_radius, expected", [
    ([0.3, -0.2, 0.15], 0.0, 0.0),    # 5 cm outside
    ([0.0, 0.0, 0.1], 0.0, 0.0),      # point touching
    ([0.0, 0.0, 0.097], 0.0, 0.003),  # 3 mm inside
    ([0.0, 0.0, 0.105], 0.01, 0.005),  # tool sphere of 1 cm, centre 5 mm outside
    ([0.0, 0.0, 0.11], 0.01, 0.0),    # tool sphere touching
    ([0.0, 0.0, 0.12], 0.01, 0.0),    # tool sphere outside
])
def test_plane_penetration_hand_computed(tip, tool_radius, expected):
    depth, direction = penetration(PLANE, np.array(tip), tool_radius)
    assert depth == pytest.approx(expected, abs=1e-12)
    np.testing.assert_allclose(direction, [0.0, 0.0, 1.0])


@pytest.mark.parametrize("tip, tool_radius, expected, direction", [
    ([0.1, 0.0, 0.08], 0.0, 0.0, [0, 0, 1]),      # 3 cm outside
    ([0.1, 0.05, 0.0], 0.0, 0.0, [0, 1, 0]),      # touching
    ([0.07, 0.0, 0.0], 0.0, 0.02, [-1, 0, 0]),    # 2 cm inside
    ([0.1, 0.0, -0.055], 0.01, 0.005, [0, 0, -1]),  # 1 cm tool, centre 5 mm outside
    ([0.1, 0.03, 0.04], 0.0, 0.0, [0, 0.6, 0.8]),  # 3-4-5 triangle: exactly on the surface
    ([0.1, 0.03, 0.04], 0.002, 0.002, [0, 0.6, 0.8]),
])
def test_sphere_penetration_hand_computed(tip, tool_radius, expected, direction):
    depth, got = penetration(SPHERE, np.array(tip), tool_radius)
    assert depth == pytest.approx(expected, abs=1e-12)
    np.testing.assert_allclose(got, direction, atol=1e-12)


def test_sphere_tip_at_the_centre_is_finite_and_fully_deep():
    depth, direction = penetration(SPHERE, np.array([0.1, 0.0, 0.0]), 0.01)
    assert depth == pytest.approx(0.06)
    assert np.isfinite(direction).all()
    assert np.linalg.norm(direction) == pytest.approx(1.0)


def test_force_direction_and_magnitude():
    depth, direction = penetration(PLANE, np.array([0.0, 0.0, 0.098]), 0.0)
    force = contact_force(depth, 0.0, direction, stiffness=500.0, damping=0.0)
    np.testing.assert_allclose(force, [0.0, 0.0, 1.0])  # 500 N/m × 2 mm along +z
    force = contact_force(depth, 0.1, direction, stiffness=500.0, damping=2.0)
    np.testing.assert_allclose(force, [0.0, 0.0, 1.2])  # going deeper at 0.1 m/s adds 0.2 N


def test_sphere_force_pushes_the_tool_out_of_the_liver():
    tip = np.array([0.1, 0.0, 0.045])
    depth, direction = penetration(SPHERE, tip, 0.0)
    force = contact_force(depth, 0.0, direction, stiffness=400.0, damping=0.0)
    np.testing.assert_allclose(force, [0.0, 0.0, 2.0])  # 400 N/m × 5 mm, radially outward


def test_damping_never_makes_the_force_pull():
    direction = np.array([0.0, 0.0, 1.0])
    for depth, rate in [(0.001, -10.0), (0.001, -0.5), (0.0, 5.0), (0.0, -5.0), (0.01, -1e6)]:
        force = contact_force(depth, rate, direction, stiffness=500.0, damping=3.0)
        assert force @ direction >= 0.0
        assert np.isfinite(force).all()
    np.testing.assert_array_equal(contact_force(0.001, -10.0, direction, 500.0, 3.0), np.zeros(3))
    np.testing.assert_array_equal(contact_force(0.0, 5.0, direction, 500.0, 3.0), np.zeros(3))


def test_quaternion_to_matrix_known_rotations():
    np.testing.assert_allclose(quaternion_to_matrix([0, 0, 0, 1]), np.eye(3), atol=1e-15)
    s = math.sqrt(0.5)
    rz90 = quaternion_to_matrix([0, 0, s, s])
    np.testing.assert_allclose(rz90 @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix([0, 0, 2, 2]), rz90, atol=1e-12)  # normalised
    with pytest.raises(ValueError, match="quaternion"):
        quaternion_to_matrix([0, 0, 0, 0])


def _random_map(rng):
    return DeviceMap(rotation=rng.normal(size=4), translation=rng.normal(size=3), scale=rng.uniform(0.2, 5.0))


def test_frame_map_round_trip_and_rigid_force_rotation():
    rng = np.random.default_rng(7)
    for _ in range(20):
        frame = _random_map(rng)
        point, force = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_allclose(frame.liver_to_device(frame.device_to_liver(point)), point, atol=1e-12)
        np.testing.assert_allclose(frame.device_to_liver(frame.liver_to_device(point)), point, atol=1e-12)
        device_force = frame.liver_to_device_force(force)
        assert np.linalg.norm(device_force) == pytest.approx(np.linalg.norm(force))  # scale ignored
        np.testing.assert_allclose(frame.rotation @ device_force, force, atol=1e-12)


def test_frame_map_hand_computed():
    s = math.sqrt(0.5)
    frame = DeviceMap(rotation=[0, 0, s, s], translation=[0.0, 0.0, 0.2], scale=2.0)  # 90° about z
    np.testing.assert_allclose(frame.device_to_liver(np.array([0.01, 0.0, 0.0])), [0.0, 0.02, 0.2], atol=1e-12)
    # A force along liver +y is along device +x; its magnitude does not depend on the scale.
    np.testing.assert_allclose(frame.liver_to_device_force(np.array([0.0, 1.5, 0.0])), [1.5, 0.0, 0.0],
                               atol=1e-12)
    matrix_frame = DeviceMap(rotation=quaternion_to_matrix([0, 0, s, s]), translation=[0, 0, 0.2], scale=2.0)
    np.testing.assert_allclose(matrix_frame.rotation, frame.rotation, atol=1e-12)


@pytest.mark.parametrize("kwargs, field", [
    ({"rotation": np.diag([1.0, 1.0, -1.0])}, "DeviceMap.rotation"),  # a reflection
    ({"rotation": 2 * np.eye(3)}, "DeviceMap.rotation"),
    ({"rotation": np.eye(2)}, "DeviceMap.rotation"),
    ({"translation": [0, np.nan, 0]}, "DeviceMap.translation"),
    ({"scale": 0.0}, "DeviceMap.scale"),
    ({"scale": -1.0}, "DeviceMap.scale"),
])
def test_frame_map_refuses_bad_fields_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        DeviceMap(**kwargs)


def test_passivity_bounds():
    assert passivity_damping_min(1000.0, 0.001) == pytest.approx(0.5)  # K·T/2
    assert max_passive_stiffness(0.5, 0.001) == pytest.approx(1000.0)  # 2b/T
    assert passivity_damping_min(1000.0, 0.001, virtual_damping=-0.2) == pytest.approx(0.7)
    assert max_passive_stiffness(0.7, 0.001, virtual_damping=0.2) == pytest.approx(1000.0)
    assert max_passive_stiffness(0.1, 0.001, virtual_damping=0.2) == 0.0
    for stiffness in (10.0, 800.0, 3000.0):
        b = passivity_damping_min(stiffness, 0.001)
        assert max_passive_stiffness(b, 0.001) == pytest.approx(stiffness)
    with pytest.raises(ValueError, match="period"):
        passivity_damping_min(1000.0, 0.0)
    with pytest.raises(ValueError, match="stiffness"):
        passivity_damping_min(-1.0, 0.001)
    with pytest.raises(ValueError, match="damping"):
        max_passive_stiffness(np.nan, 0.001)


def test_blend_interpolates_planes_and_spheres_and_falls_back_to_the_target():
    start, target = LocalModel.plane((0, 0, 0), (0, 0, 1)), LocalModel.plane((0, 0, -0.01), (0, 1, 1))
    half = blend(start, target, 0.5)
    np.testing.assert_allclose(half.point, (0, 0, -0.005))
    bisector = np.array([0, 0, 1]) + np.array([0, 1, 1]) / np.sqrt(2)  # halfway between the unit normals
    np.testing.assert_allclose(half.normal, bisector / np.linalg.norm(bisector))
    assert blend(start, target, 1.5) is target and blend(None, target, 0.2) is target
    sphere = LocalModel.sphere((0, 0, 0), 0.1)
    assert blend(sphere, target, 0.5) is target  # another kind: no blend
    assert blend(LocalModel.plane((0, 0, 0), (0, 0, -1)), start, 0.5) is start  # opposite normals
    quarter = blend(sphere, LocalModel.sphere((0.04, 0, 0), 0.2), 0.25)
    np.testing.assert_allclose(quarter.centre, (0.01, 0, 0))
    assert quarter.radius_m == pytest.approx(0.125)


def test_glide_spreads_a_physics_step_of_the_surface_over_the_ticks():
    tick, frame = 0.001, 1.0 / 150.0
    glide, at_once = ModelGlide(frame), ModelGlide(0.0)
    tip = np.array([0.0, 0.0, 0.0])
    depths = {id(glide): [], id(at_once): []}
    models = [LocalModel.plane((0, 0, -0.001 * k), (0, 0, 1)) for k in range(4)]  # the surface recedes 1 mm a frame
    for i in range(int(3.5 * frame / tick)):
        now = i * tick
        newest = models[min(int(now / frame), 3)]
        for renderer in (glide, at_once):
            depths[id(renderer)].append(penetration(renderer.update(newest, now), tip, 0.002)[0])
    jumps_glide = np.abs(np.diff(depths[id(glide)])).max()
    jumps_at_once = np.abs(np.diff(depths[id(at_once)])).max()
    assert jumps_at_once == pytest.approx(0.001)
    assert jumps_glide < jumps_at_once / 4  # one frame step spread over its ticks (~1/6.7 each)
    assert glide.update(None, 1.0) is None and glide.update(models[0], 1.001) is models[0]  # after a gap: at once
    with pytest.raises(ValueError, match="duration_s must be finite and >= 0"):
        ModelGlide(-1.0)
