"""msg_defs.local_model: the local model as the /liver/contact_plane Marker and back, from the message and
from its bytes (the bridge's path), refusals naming the field."""
import numpy as np
import pytest
from geometry_msgs.msg import Point
from msg_samples import AXES
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, UVCoordinate

from liver_sim.base.local_model import LocalModel
from msg_defs.local_model import (
    DEPTH_KEY,
    PLANE_THICKNESS_M,
    STIFFNESS_KEY,
    local_model_from_bytes,
    local_model_marker,
    marker_to_local_model,
)


def plane_model(point, normal):
    return LocalModel("plane", True, np.asarray(point, float), np.asarray(normal, float), np.zeros(3), 0.0, 0.001, True)


def sphere_model(centre, radius):
    return LocalModel("sphere", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.asarray(centre, float), radius,
                      0.0, False)


def _through_the_wire(marker):
    return deserialize_message(serialize_message(marker), Marker)


def _both_ways(marker):
    """marker_to_local_model of the message through the wire, checked against local_model_from_bytes of its
    bytes (the bridge's path): the same model, field by field, and the same lifetime."""
    model, lifetime_s = marker_to_local_model(_through_the_wire(marker))
    from_bytes, lifetime_from_bytes = local_model_from_bytes(serialize_message(marker))
    assert lifetime_from_bytes == pytest.approx(lifetime_s, abs=1e-12)
    assert (model is None) == (from_bytes is None)
    if model is not None:
        for name in ("kind", "valid", "radius_m", "stiffness_n_per_m", "depth_m"):
            assert getattr(from_bytes, name) == getattr(model, name)
        for name in ("point", "normal", "centre"):
            np.testing.assert_array_equal(getattr(from_bytes, name), getattr(model, name))
    return model, lifetime_s


@pytest.mark.parametrize("normal", AXES)
def test_plane_local_model_round_trip(normal):
    point = (0.01, -0.02, 0.03)
    marker = local_model_marker(plane_model(point, normal), 4.0, "liver", 0.05, patch_size_m=0.03)
    assert (marker.ns, marker.id, marker.type, marker.action) == ("local_model", 0, Marker.CUBE, Marker.ADD)
    assert (marker.scale.x, marker.scale.y, marker.scale.z) == (0.03, 0.03, PLANE_THICKNESS_M)
    model, lifetime_s = _both_ways(marker)
    assert model.kind == "plane" and lifetime_s == pytest.approx(0.05)
    np.testing.assert_array_equal(model.point, point)
    np.testing.assert_allclose(model.normal, np.asarray(normal) / np.linalg.norm(normal), atol=1e-12)


def test_plane_local_model_round_trip_random_normals(rng):
    for normal in rng.normal(size=(20, 3)):
        model, _ = marker_to_local_model(local_model_marker(plane_model(np.zeros(3), normal), 0.0, "l", 0.05))
        np.testing.assert_allclose(model.normal, normal / np.linalg.norm(normal), atol=1e-12)


def test_sphere_local_model_round_trip():
    marker = local_model_marker(sphere_model((0.0, 0.1, -0.2), 0.07), 4.0, "liver", 0.02)
    assert marker.type == Marker.SPHERE and (marker.scale.x, marker.scale.y, marker.scale.z) == (0.14, 0.14, 0.14)
    model, lifetime_s = _both_ways(marker)
    assert model.kind == "sphere" and lifetime_s == pytest.approx(0.02)
    np.testing.assert_array_equal(model.centre, (0.0, 0.1, -0.2))
    assert model.radius_m == pytest.approx(0.07)


def test_invalid_local_model_is_a_delete_marker_read_as_none():
    marker = local_model_marker(LocalModel.invalid(), 4.0, "liver", 0.05)
    assert (marker.ns, marker.id, marker.action, marker.header.frame_id) == ("local_model", 0, Marker.DELETE, "liver")
    assert _both_ways(marker) == (None, pytest.approx(0.05))
    assert marker_to_local_model(Marker(action=Marker.DELETEALL)) == (None, 0.0)


def test_local_model_marker_refuses_bad_models():
    with pytest.raises(ValueError, match=r"LocalModel\.point must be finite"):
        local_model_marker(plane_model((0, np.nan, 0), (0, 0, 1)), 0.0, "liver", 0.05)
    with pytest.raises(ValueError, match=r"LocalModel\.radius_m must be finite and > 0"):
        local_model_marker(sphere_model((0, 0, 0), 0.0), 0.0, "liver", 0.05)
    with pytest.raises(ValueError, match="lifetime_s"):
        local_model_marker(plane_model((0, 0, 0), (0, 0, 1)), 0.0, "liver", -0.05)


def _marker(**changes):
    marker = local_model_marker(sphere_model((0.0, 0.0, 0.0), 0.05), 0.0, "liver", 0.05)
    for path, value in changes.items():
        owner = marker
        *parents, leaf = path.split("__")
        for name in parents:
            owner = getattr(owner, name)
        setattr(owner, leaf, value)
    return marker


@pytest.mark.parametrize("changes, message", [
    ({"pose__position__x": float("nan")}, r"Marker\.pose\.position must be finite"),
    ({"pose__orientation__w": 0.0}, r"Marker\.pose\.orientation must be a non-zero quaternion"),
    ({"pose__orientation__y": float("inf")}, r"Marker\.pose\.orientation must be finite"),
    ({"scale__x": 0.0}, r"Marker\.scale\.x must be finite and > 0"),
    ({"scale__x": float("nan")}, r"Marker\.scale\.x must be finite and > 0"),
    ({"type": Marker.ARROW}, r"Marker\.type is 0, expected CUBE \(1\) or SPHERE \(2\)"),
    ({"action": 5}, r"Marker\.action is 5"),
])
def test_bad_local_model_marker_is_refused_by_field(changes, message):
    with pytest.raises(ValueError, match=message):
        marker_to_local_model(_marker(**changes))
    with pytest.raises(ValueError, match=message):
        local_model_from_bytes(serialize_message(_marker(**changes)))


def test_local_model_from_bytes_skips_every_field_a_marker_may_fill():
    marker = _marker(text=f"note=1 {STIFFNESS_KEY}=34.5", frame_locked=True, texture_resource="embedded://x",
                     mesh_resource="package://m.dae")
    marker.points = [Point(x=float(k)) for k in range(3)]
    marker.colors = [ColorRGBA(r=1.0)] * 2
    marker.texture.header.frame_id, marker.texture.format, marker.texture.data = "camera", "png", [1, 2, 3]
    marker.uv_coordinates = [UVCoordinate(u=0.5, v=0.25)] * 5
    model, _ = _both_ways(marker)
    assert model.stiffness_n_per_m == 34.5


@pytest.mark.parametrize("cut", [0, 3, 20, 60, 150])
def test_truncated_marker_bytes_are_refused_naming_the_field(cut):
    data = serialize_message(_marker(text=f"{STIFFNESS_KEY}=34.5"))
    with pytest.raises(ValueError, match=r"^Marker(\.[a-z_.]+|, type, action)?: (not a CDR message|truncated|bad)"):
        local_model_from_bytes(data[:cut])


def test_an_oversized_marker_is_refused_before_it_is_read():
    data = serialize_message(_marker(text="x " * 1_000_000))  # 2 MB
    with pytest.raises(ValueError, match=r"^Marker: 2000\d+ bytes, more than the 4096"):
        local_model_from_bytes(data)


@pytest.mark.parametrize("text, stiffness", [(f"note=1 {STIFFNESS_KEY}=34.5", 34.5), (f"{STIFFNESS_KEY}=7", 7.0),
                                             (f"x{STIFFNESS_KEY}=7", None), ("", None),
                                             (f"a\t{STIFFNESS_KEY}=2 {STIFFNESS_KEY}=3", 2.0)])
def test_the_stiffness_is_the_first_entry_with_its_key(text, stiffness):
    model, _ = _both_ways(_marker(text=text))
    assert model.stiffness_n_per_m == stiffness


@pytest.mark.parametrize("kind", ["plane", "sphere"])
def test_the_depth_at_the_physics_pose_travels_beside_the_stiffness(kind):
    model = LocalModel(kind, True, np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.05,
                       0.0023, True, 350.0)
    marker = local_model_marker(model, 0.0, "liver", 0.05)
    assert marker.text == f"{STIFFNESS_KEY}=350.0 {DEPTH_KEY}=0.0023"
    read, _ = _both_ways(marker)
    assert (read.stiffness_n_per_m, read.depth_m) == (350.0, 0.0023)


def test_a_model_without_stiffness_carries_no_depth():
    marker = local_model_marker(plane_model((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), 0.0, "liver", 0.05)
    assert marker.text == ""
    read, _ = _both_ways(marker)
    assert read.stiffness_n_per_m is None and read.depth_m == 0.0


@pytest.mark.parametrize("text, depth", [(f"{STIFFNESS_KEY}=34.5", 0.0),  # a Marker from before the entry
                                         ("", 0.0), (f"{DEPTH_KEY}=0", 0.0), (f"x{DEPTH_KEY}=1", 0.0),
                                         (f"note=1\t{DEPTH_KEY}=1e-3 {DEPTH_KEY}=2", 0.001)])
def test_the_depth_is_the_first_entry_with_its_key_and_zero_without_one(text, depth):
    model, _ = _both_ways(_marker(text=text))
    assert model.depth_m == depth


@pytest.mark.parametrize("value", ["nan", "inf", "-0.001", "deep", ""])
def test_a_bad_depth_is_refused_by_name(value):
    text = f"{STIFFNESS_KEY}=34.5 {DEPTH_KEY}={value}"
    message = r"Marker\.text depth_m must be a finite number >= 0"
    with pytest.raises(ValueError, match=message):
        marker_to_local_model(_marker(text=text))
    with pytest.raises(ValueError, match=message):
        local_model_from_bytes(serialize_message(_marker(text=text)))


def test_a_model_with_a_bad_depth_is_not_written():
    model = LocalModel("plane", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0, -0.001, True, 34.5)
    with pytest.raises(ValueError, match=r"LocalModel\.depth_m must be finite and >= 0"):
        local_model_marker(model, 0.0, "liver", 0.05)
