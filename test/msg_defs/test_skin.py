"""msg_defs.skin: the skin as a Mesh and back, as a TRIANGLE_LIST Marker and as that Marker's bytes."""
import numpy as np
import pytest
from msg_samples import random_skin
from rclpy.serialization import deserialize_message, serialize_message
from shape_msgs.msg import Mesh
from visualization_msgs.msg import Marker

from msg_defs.skin import mesh_msg_to_arrays, skin_marker, skin_marker_serialized, skin_mesh_msg
from msg_defs.stamps import stamp_from_seconds


def test_mesh_round_trip(rng):
    points, skin = rng.random((40, 3)), random_skin(rng, 40, 60)
    msg = deserialize_message(serialize_message(skin_mesh_msg(skin, points)), Mesh)
    back_skin, back_points = mesh_msg_to_arrays(msg)
    np.testing.assert_array_equal(back_skin, skin)
    np.testing.assert_array_equal(back_points, points)
    assert back_skin.dtype == np.int64


def test_mesh_refuses_indices_out_of_range_both_ways(rng):
    points = rng.random((4, 3))
    with pytest.raises(ValueError, match=r"skin holds node indices outside \[0, 4\)"):
        skin_mesh_msg(np.array([[0, 1, 4]]), points)
    msg = skin_mesh_msg(np.array([[0, 1, 3]]), points)
    msg.vertices.pop()
    with pytest.raises(ValueError, match=r"Mesh\.triangles holds node indices outside \[0, 3\)"):
        mesh_msg_to_arrays(msg)
    msg.vertices[0].y = float("inf")
    with pytest.raises(ValueError, match=r"Mesh\.vertices must be finite"):
        mesh_msg_to_arrays(msg)


def test_skin_marker_lists_the_triangle_corners_in_order(rng):
    positions, skin = rng.random((30, 3)), random_skin(rng, 30, 20)
    marker = skin_marker(positions, skin, 2.0, "liver")
    assert (marker.ns, marker.id, marker.type, marker.action) == ("liver", 0, Marker.TRIANGLE_LIST, Marker.ADD)
    assert marker.pose.orientation.w == 1.0 and marker.color.a == 1.0
    corners = np.array([(p.x, p.y, p.z) for p in marker.points])
    np.testing.assert_array_equal(corners, positions[skin].reshape(-1, 3))


@pytest.mark.parametrize("n_triangles", [0, 1, 450])
def test_serialized_skin_marker_is_the_same_message(rng, n_triangles):
    positions, skin = rng.random((300, 3)), random_skin(rng, 300, n_triangles)
    stamp = stamp_from_seconds(5.25)
    expected = deserialize_message(serialize_message(skin_marker(positions, skin, stamp, "liver")), Marker)
    assert deserialize_message(skin_marker_serialized(positions, skin, stamp, "liver"), Marker) == expected
