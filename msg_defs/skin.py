"""The skin: its triangles over the rest positions as shape_msgs/Mesh (/liver/surface) and back, over the deformed
positions as a TRIANGLE_LIST Marker (/liver/marker)."""
from __future__ import annotations

import struct

import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from rclpy.serialization import serialize_message
from shape_msgs.msg import Mesh, MeshTriangle
from visualization_msgs.msg import Marker

from msg_defs.finite import colour_msg, finite_array
from msg_defs.stamps import header_msg

SKIN_COLOUR = (0.6, 0.25, 0.2, 1.0)
# A point no simulation produces, to find where the rmw writes Marker.points (skin_marker_serialized).
_PROBE = (-1.2345678901234567e-300, 9.876543210987654e300, -3.141592653589793e-150)
_PROBE_BYTES = struct.pack("<3d", *_PROBE)
_CDR_LITTLE_ENDIAN = b"\x00\x01"


def _skin(skin, n_points: int, name: str) -> np.ndarray:
    """(K, 3) int64 triangle node indices, each in [0, n_points), or ValueError naming `name`."""
    tri = np.asarray(skin)
    if tri.ndim != 2 or tri.shape[1] != 3 or not (tri.size == 0 or np.issubdtype(tri.dtype, np.integer)):
        raise ValueError(f"{name} must be a (K, 3) integer array, got shape {tri.shape} of {tri.dtype}")
    if tri.size and (tri.min() < 0 or tri.max() >= n_points):
        raise ValueError(f"{name} holds node indices outside [0, {n_points}): min {tri.min()}, max {tri.max()}")
    return tri.astype(np.int64, copy=False)


def _points(xyz: np.ndarray) -> list:
    """geometry_msgs/Point list of the rows of a finite (N, 3) array."""
    return [Point(x=x, y=y, z=z) for x, y, z in xyz.tolist()]


def skin_mesh_msg(skin, rest_points) -> Mesh:
    """shape_msgs/Mesh: triangles = the (K, 3) skin as indices into /liver/nodes, vertices = the (N, 3)
    rest positions (m)."""
    points = finite_array(rest_points, (-1, 3), "rest_points")
    triangles = _skin(skin, len(points), "skin").astype(np.uint32)
    return Mesh(triangles=[MeshTriangle(vertex_indices=row) for row in triangles], vertices=_points(points))


def mesh_msg_to_arrays(msg: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(skin (K, 3) int64, rest points (N, 3) float64 m) from a shape_msgs/Mesh; refuses non-finite
    vertices and indices outside the vertices."""
    points = finite_array([(p.x, p.y, p.z) for p in msg.vertices] or np.empty((0, 3)), (-1, 3), "Mesh.vertices")
    skin = np.array([t.vertex_indices for t in msg.triangles], dtype=np.int64).reshape(-1, 3)
    return _skin(skin, len(points), "Mesh.triangles"), points


def _skin_marker_without_points(stamp, frame_id: str, colour) -> Marker:
    return Marker(header=header_msg(stamp, frame_id), ns="liver", id=0, type=Marker.TRIANGLE_LIST, action=Marker.ADD,
                  pose=Pose(orientation=Quaternion(w=1.0)), scale=Vector3(x=1.0, y=1.0, z=1.0),
                  color=colour_msg(colour))


def _corners(positions, skin) -> np.ndarray:
    """(3K, 3) corners of the skin triangles, in order."""
    points = finite_array(positions, (-1, 3), "positions")
    return points[_skin(skin, len(points), "skin")].reshape(-1, 3)


def skin_marker(positions, skin, stamp, frame_id: str, colour=SKIN_COLOUR) -> Marker:
    """TRIANGLE_LIST Marker of the deformed skin (ns "liver", id 0): points = the corners (m) of the
    (K, 3) skin triangles over the (N, 3) `positions`, in order; colour = (r, g, b, a)."""
    marker = _skin_marker_without_points(stamp, frame_id, colour)
    marker.points = _points(_corners(positions, skin))
    return marker


def skin_marker_serialized(positions, skin, stamp, frame_id: str, colour=SKIN_COLOUR) -> bytes:
    """The serialized (CDR) form of :func:`skin_marker`, for ``Publisher.publish(bytes)``.

    Builds no Point objects: the rmw serializes the marker with one probe point, and the corners are
    written over it as one numpy block (a sequence of Point is a uint32 count, padding to 8 bytes,
    then x, y, z doubles). Loads rclpy's serializer (no node, no context needed).
    """

    corners = _corners(positions, skin)
    marker = _skin_marker_without_points(stamp, frame_id, colour)
    without = serialize_message(marker)
    if len(corners) == 0:
        return without
    marker.points = [Point(x=_PROBE[0], y=_PROBE[1], z=_PROBE[2])]
    probe = serialize_message(marker)
    start = probe.find(_PROBE_BYTES)
    padding = len(probe) - len(without) - len(_PROBE_BYTES)
    if probe[:2] != _CDR_LITTLE_ENDIAN or start < 0 or (start - 4) % 8 or padding not in (0, 4):
        raise RuntimeError("unexpected CDR layout of visualization_msgs/Marker.points")
    count_at = start - 4 - padding
    return b"".join((probe[:count_at], struct.pack("<I", len(corners)), probe[count_at + 4:start],
                     np.ascontiguousarray(corners, dtype="<f8"), probe[start + len(_PROBE_BYTES):]))
