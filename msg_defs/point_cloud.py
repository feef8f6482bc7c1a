"""Node positions (/liver/nodes) as PointCloud2 (a message, or its bytes), and back."""
from __future__ import annotations

import array
import functools
import struct

import numpy as np
from numpy.lib.recfunctions import structured_to_unstructured
from rclpy.serialization import serialize_message
from sensor_msgs.msg import PointCloud2, PointField

from msg_defs.finite import finite_array
from msg_defs.stamps import header_msg, stamp_parts


def nodes_to_pointcloud2(positions, stamp, frame_id: str) -> PointCloud2:
    """One point per node (m), row order = node index: fields x y z FLOAT32 at offsets 0, 4, 8,
    point_step 12, height 1, little-endian, dense."""
    xyz = finite_array(positions, (-1, 3), "positions", dtype="<f4")
    n = len(xyz)
    fields = [PointField(name=axis, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, axis in enumerate("xyz")]
    return PointCloud2(header=header_msg(stamp, frame_id), height=1, width=n, fields=fields, is_bigendian=False,
                       point_step=12, row_step=12 * n, data=array.array("B", xyz.tobytes()), is_dense=True)


@functools.lru_cache(maxsize=4)
def _pointcloud2_template(nodes: int, frame_id: str) -> tuple[bytes, int]:
    """(serialized nodes_to_pointcloud2 of `nodes` zero points, stamp 0, the offset of its point data): every
    field but the stamp and the points is the same for a node count and a frame."""
    template = serialize_message(nodes_to_pointcloud2(np.zeros((nodes, 3)), (0, 0), frame_id))
    return template, len(template) - 1 - 12 * nodes  # the data, then is_dense (one byte) last


def nodes_pointcloud2_bytes(positions, stamp, frame_id: str) -> bytes:
    """The serialized :func:`nodes_to_pointcloud2` (for ``Publisher.publish(bytes)``), without a message object:
    a template of the node count (cached) with the stamp and the points written in."""
    xyz = finite_array(positions, (-1, 3), "positions", dtype="<f4")
    template, data_at = _pointcloud2_template(len(xyz), frame_id)
    message = bytearray(template)
    struct.pack_into("<iI", message, 4, *stamp_parts(stamp))
    message[data_at:data_at + xyz.nbytes] = xyz.tobytes()
    return bytes(message)


def pointcloud2_to_nodes(msg: PointCloud2) -> np.ndarray:
    """(N, 3) float64 positions (m) from a PointCloud2 with FLOAT32 fields x, y, z at any offsets.

    Refuses, naming the field: point_step < 12, row_step ≠ point_step·width, len(data) ≠ row_step·height,
    a missing, non-FLOAT32 or out-of-point x/y/z field, non-finite coordinates.
    """
    if msg.point_step < 12:
        raise ValueError(f"PointCloud2.point_step is {msg.point_step}, expected >= 12 (x, y, z float32)")
    if msg.row_step != msg.point_step * msg.width:
        raise ValueError(f"PointCloud2.row_step is {msg.row_step}, expected point_step*width = "
                         f"{msg.point_step * msg.width}")
    if len(msg.data) != msg.row_step * msg.height:
        raise ValueError(f"PointCloud2.data has {len(msg.data)} bytes, expected row_step*height = "
                         f"{msg.row_step * msg.height}")
    by_name = {field.name: field for field in reversed(msg.fields)}
    offsets = []
    for axis in "xyz":
        field = by_name.get(axis)
        label = f"PointCloud2.fields['{axis}']"
        if field is None:
            raise ValueError(f"PointCloud2.fields has no '{axis}' field, got {[f.name for f in msg.fields]}")
        if field.datatype != PointField.FLOAT32:
            raise ValueError(f"{label}.datatype is {field.datatype}, expected {PointField.FLOAT32} (FLOAT32)")
        if field.count < 1:
            raise ValueError(f"{label}.count is {field.count}, expected >= 1")
        if field.offset + 4 > msg.point_step:
            raise ValueError(f"{label}.offset is {field.offset}, beyond point_step {msg.point_step}")
        offsets.append(field.offset)
    layout = np.dtype({"names": ["x", "y", "z"], "formats": [">f4" if msg.is_bigendian else "<f4"] * 3,
                       "offsets": offsets, "itemsize": msg.point_step})
    records = np.frombuffer(msg.data, dtype=layout, count=msg.width * msg.height)
    xyz = structured_to_unstructured(records, dtype=np.float64)
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        raise ValueError(f"PointCloud2.data holds non-finite coordinates (first at point {int(np.argmin(finite))})")
    return xyz
