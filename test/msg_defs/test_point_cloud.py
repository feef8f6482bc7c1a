"""msg_defs.point_cloud: node positions as PointCloud2 (a message, or its bytes) and back, foreign layouts, refusals
naming the field."""
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField

from msg_defs.point_cloud import nodes_pointcloud2_bytes, nodes_to_pointcloud2, pointcloud2_to_nodes
from msg_defs.stamps import seconds_from_stamp


def test_pointcloud_round_trip_is_exact_in_float32(rng):
    positions = rng.normal(scale=0.1, size=(2000, 3))
    msg = nodes_to_pointcloud2(positions, 3.5, "liver")
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 2000, 12, 24000)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, PointField.FLOAT32, 1), ("y", 4, PointField.FLOAT32, 1), ("z", 8, PointField.FLOAT32, 1)]
    assert msg.is_dense and not msg.is_bigendian
    assert msg.header.frame_id == "liver" and seconds_from_stamp(msg.header.stamp) == 3.5
    back = pointcloud2_to_nodes(deserialize_message(serialize_message(msg), PointCloud2))
    assert back.dtype == np.float64 and back.shape == (2000, 3)
    np.testing.assert_array_equal(back, positions.astype(np.float32))


def test_pointcloud_accepts_other_layouts(rng):
    """Foreign clouds: padded points, fields out of order, extra fields, big-endian, two rows."""
    xyz = rng.random((6, 3)).astype(np.float32)
    for endian, bigendian in (("<", False), (">", True)):
        layout = np.dtype({"names": ["intensity", "z", "x", "y"], "formats": [endian + "f4"] * 4,
                           "offsets": [0, 4, 12, 20], "itemsize": 32})
        records = np.zeros(6, dtype=layout)
        records["x"], records["y"], records["z"] = xyz.T
        fields = [PointField(name=name, offset=offset, datatype=PointField.FLOAT32, count=1)
                  for name, offset in (("intensity", 0), ("z", 4), ("x", 12), ("y", 20))]
        msg = PointCloud2(height=2, width=3, fields=fields, is_bigendian=bigendian, point_step=32, row_step=96,
                          data=records.tobytes(), is_dense=True)
        np.testing.assert_array_equal(pointcloud2_to_nodes(msg), xyz)


def _cloud_with(**changes):
    msg = nodes_to_pointcloud2(np.arange(30.0).reshape(10, 3), 0.0, "liver")
    for key, value in changes.items():
        setattr(msg, key, value)
    return msg


def _field(name, offset, datatype=PointField.FLOAT32):
    return PointField(name=name, offset=offset, datatype=datatype, count=1)


def _nan_data():
    data = np.arange(30.0, dtype="<f4")
    data[17] = np.nan
    return data.tobytes()


@pytest.mark.parametrize("changes, message", [
    ({"data": bytes(100)}, r"PointCloud2\.data has 100 bytes, expected row_step\*height = 120"),
    ({"row_step": 100}, r"PointCloud2\.row_step is 100"),
    ({"point_step": 8, "row_step": 80}, r"PointCloud2\.point_step is 8"),
    ({"fields": [_field("x", 0), _field("z", 8)]}, r"PointCloud2\.fields has no 'y' field"),
    ({"fields": [_field("x", 0), _field("y", 4, PointField.FLOAT64), _field("z", 8)]},
     r"PointCloud2\.fields\['y'\]\.datatype is 8, expected 7"),
    ({"fields": [_field("x", 0), _field("y", 4), _field("z", 10)]}, r"PointCloud2\.fields\['z'\]\.offset is 10"),
    ({"data": _nan_data()}, r"PointCloud2\.data holds non-finite coordinates \(first at point 5\)"),
], ids=["data length", "row_step", "point_step", "missing field", "datatype", "offset", "NaN"])
def test_malformed_pointcloud_is_refused_naming_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        pointcloud2_to_nodes(_cloud_with(**changes))


@pytest.mark.parametrize("positions, message", [
    (np.array([[0.0, np.nan, 0.0]]), r"positions must be finite .* at index \[0, 1\]"),
    (np.array([[0.0, 1e39, 0.0]]), r"positions must be finite \(float32\)"),
    (np.zeros((4, 2)), r"positions must have shape \(N, 3\)"),
])
def test_pointcloud_builder_refuses_what_would_not_be_finite_float32(positions, message):
    with pytest.raises(ValueError, match=message):
        nodes_to_pointcloud2(positions, 0.0, "liver")


def test_the_cloud_bytes_are_the_cloud_message_for_every_stamp_and_position_of_a_node_count(rng):
    """The bytes come from a template cached per node count and frame: each call writes its own stamp and points."""
    for stamp in ((1, 2), 3.5, (4, 999_999_999)):
        positions = rng.normal(scale=0.1, size=(50, 3))
        data = nodes_pointcloud2_bytes(positions, stamp, "liver")
        assert deserialize_message(data, PointCloud2) == nodes_to_pointcloud2(positions, stamp, "liver")
    other = nodes_pointcloud2_bytes(np.ones((2, 3)), (1, 2), "world")
    assert deserialize_message(other, PointCloud2) == nodes_to_pointcloud2(np.ones((2, 3)), (1, 2), "world")
    with pytest.raises(ValueError, match=r"^positions must be finite \(float32\)"):
        nodes_pointcloud2_bytes(np.full((50, 3), 1e39), (1, 2), "liver")
