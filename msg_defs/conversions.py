"""numpy ↔ ROS messages: the one place where the simulator's arrays become messages and back.

SI units: metres, seconds, newtons. A `stamp` argument is a builtin_interfaces/Time or a time in
seconds (float). Builders refuse non-finite input with a ValueError naming the argument, so no NaN
or inf reaches the wire; readers refuse a malformed message with a ValueError naming the field.
Bulk arrays travel as numpy bytes; only point lists (Marker, Mesh) are built point by point,
because rosidl Python messages hold nested messages as Python objects.
"""
from __future__ import annotations

import array
import math
import struct

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3, Wrench, WrenchStamped
from numpy.lib.recfunctions import structured_to_unstructured
from sensor_msgs.msg import PointCloud2, PointField
from shape_msgs.msg import Mesh, MeshTriangle
from std_msgs.msg import ColorRGBA, Float64MultiArray, Header, MultiArrayDimension
from visualization_msgs.msg import Marker

from liver_sim.checks import positive
from liver_sim.geometry.device_map import DeviceMap
from liver_sim.geometry.rotations import quaternion_from_z_axis, quaternion_to_matrix
from liver_sim.local_model import LocalModel
from msg_defs import cdr

SKIN_COLOUR = (0.6, 0.25, 0.2, 1.0)
PLANE_COLOUR = (0.2, 0.8, 0.3, 0.5)
SPHERE_COLOUR = (0.2, 0.5, 0.9, 0.3)
#: Thickness (m) of the CUBE that draws a plane local model.
PLANE_THICKNESS_M = 0.001
FORCE_OUTPUT_FORMATS = ("wrench_stamped", "wrench", "vector3", "float64_array", "omni_feedback")
_FORCE_TYPES = {"wrench_stamped": WrenchStamped, "wrench": Wrench, "vector3": Vector3,
                "float64_array": Float64MultiArray}
_NANO = 1_000_000_000
# A point no simulation produces, to find where the rmw writes Marker.points (skin_marker_serialized).
_PROBE = (-1.2345678901234567e-300, 9.876543210987654e300, -3.141592653589793e-150)
_PROBE_BYTES = struct.pack("<3d", *_PROBE)
_CDR_LITTLE_ENDIAN = b"\x00\x01"


def _finite(value, shape: tuple, name: str, dtype=np.float64) -> np.ndarray:
    """`value` as a finite array of `shape` (-1 = any length) and `dtype`, or ValueError naming `name`."""
    with np.errstate(over="ignore", invalid="ignore"):
        arr = np.asarray(value, dtype=dtype)
    if arr.ndim != len(shape) or any(want not in (-1, got) for want, got in zip(shape, arr.shape)):
        wanted = ", ".join("N" if want == -1 else str(want) for want in shape)
        raise ValueError(f"{name} must have shape ({wanted}), got {arr.shape}")
    finite = np.isfinite(arr)
    if not finite.all():
        first = np.argwhere(~finite)[0].tolist()
        raise ValueError(f"{name} must be finite ({np.dtype(dtype).name}), got {arr[tuple(first)]} at index {first}")
    return arr


def _unit_quaternion(value, name: str) -> np.ndarray:
    """A finite, non-zero (x, y, z, w) quaternion, normalised, or ValueError naming `name`.

    Scaled by its largest component before the norm, so that neither huge (1e200) nor tiny (1e-200)
    components overflow or underflow into a zero quaternion.  Four finite floats (a decoded message, a (4,)
    array) take a scalar path: a 1 kHz loop calls this for every pose."""
    if type(value) is tuple or (type(value) is np.ndarray and value.shape == (4,)):
        components = tuple(map(float, value))
        if len(components) == 4 and all(map(math.isfinite, components)):
            largest = max(map(abs, components))
            if largest > 0.0:
                x, y, z, w = (c / largest for c in components)
                norm = math.sqrt(x * x + y * y + z * z + w * w)
                return np.array((x / norm, y / norm, z / norm, w / norm))
    q = _finite(value, (4,), name)
    largest = float(np.abs(q).max())
    if not largest > 0.0:
        raise ValueError(f"{name} must be a non-zero quaternion (x, y, z, w), got {q.tolist()}")
    q = q / largest
    return q / float(np.linalg.norm(q))


def _skin(skin, n_points: int, name: str) -> np.ndarray:
    """(K, 3) int64 triangle node indices, each in [0, n_points), or ValueError naming `name`."""
    tri = np.asarray(skin)
    if tri.ndim != 2 or tri.shape[1] != 3 or not (tri.size == 0 or np.issubdtype(tri.dtype, np.integer)):
        raise ValueError(f"{name} must be a (K, 3) integer array, got shape {tri.shape} of {tri.dtype}")
    if tri.size and (tri.min() < 0 or tri.max() >= n_points):
        raise ValueError(f"{name} holds node indices outside [0, {n_points}): min {tri.min()}, max {tri.max()}")
    return tri.astype(np.int64, copy=False)


def _time_parts(seconds, name: str) -> tuple[int, int]:
    """(sec, nanosec) of a time ≥ 0 s, nanoseconds rounded to nearest."""
    t = float(seconds)
    if not (math.isfinite(t) and 0.0 <= t < 2.0 ** 31):
        raise ValueError(f"{name} must be finite and in [0, 2**31) s, got {seconds!r}")
    sec = math.floor(t)
    nanosec = round((t - sec) * 1e9)
    if nanosec == _NANO:
        sec, nanosec = sec + 1, 0
    return int(sec), int(nanosec)


def stamp_from_seconds(t: float) -> Time:
    """builtin_interfaces/Time of `t` seconds (finite, ≥ 0), to the nearest nanosecond."""
    sec, nanosec = _time_parts(t, "stamp")
    return Time(sec=sec, nanosec=nanosec)


def stamp_s_from_bytes(data: bytes, type_name: str) -> float:
    """Seconds of the header stamp of a serialized stamped message (one that begins with a Header)."""
    sec, nanosec = cdr.stamp(data, type_name)
    return sec + nanosec * 1e-9


def seconds_from_stamp(stamp) -> float:
    """Seconds of a builtin_interfaces/Time (or Duration): sec + nanosec·1e-9."""
    return stamp.sec + stamp.nanosec * 1e-9


def _duration(seconds, name: str) -> Duration:
    sec, nanosec = _time_parts(seconds, name)
    return Duration(sec=sec, nanosec=nanosec)


def _stamp_parts(stamp) -> tuple[int, int]:
    """(sec, nanosec) of a builtin_interfaces/Time, a (sec, nanosec) pair or a time in seconds."""
    if isinstance(stamp, Time):
        return stamp.sec, stamp.nanosec
    if isinstance(stamp, tuple):
        return stamp
    return _time_parts(stamp, "stamp")


def _finite_floats(values: tuple, shape: tuple, name: str) -> tuple:
    """`values` unchanged when all are finite floats; else the ValueError of :func:`_finite` naming `name`."""
    if not all(map(math.isfinite, values)):
        _finite(values, shape, name)
    return values


def _header(stamp, frame_id: str) -> Header:
    sec, nanosec = _stamp_parts(stamp)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


def _vector3_msg(value, name: str) -> Vector3:
    x, y, z = _finite(value, (3,), name).tolist()
    return Vector3(x=x, y=y, z=z)


def _colour(rgba) -> ColorRGBA:
    r, g, b, a = _finite(rgba, (4,), "colour").tolist()
    return ColorRGBA(r=r, g=g, b=b, a=a)


def _points(xyz: np.ndarray) -> list:
    """geometry_msgs/Point list of the rows of a finite (N, 3) array."""
    return [Point(x=x, y=y, z=z) for x, y, z in xyz.tolist()]


# ---------------------------------------------------------------- node positions: PointCloud2

def nodes_to_pointcloud2(positions, stamp, frame_id: str) -> PointCloud2:
    """One point per node (m), row order = node index: fields x y z FLOAT32 at offsets 0, 4, 8,
    point_step 12, height 1, little-endian, dense."""
    xyz = _finite(positions, (-1, 3), "positions", dtype="<f4")
    n = len(xyz)
    fields = [PointField(name=axis, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, axis in enumerate("xyz")]
    return PointCloud2(header=_header(stamp, frame_id), height=1, width=n, fields=fields, is_bigendian=False,
                       point_step=12, row_step=12 * n, data=array.array("B", xyz.tobytes()), is_dense=True)


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


# ---------------------------------------------------------------- skin: Mesh and Marker

def skin_mesh_msg(skin, rest_points) -> Mesh:
    """shape_msgs/Mesh: triangles = the (K, 3) skin as indices into /liver/nodes, vertices = the (N, 3)
    rest positions (m)."""
    points = _finite(rest_points, (-1, 3), "rest_points")
    triangles = _skin(skin, len(points), "skin").astype(np.uint32)
    return Mesh(triangles=[MeshTriangle(vertex_indices=row) for row in triangles], vertices=_points(points))


def mesh_msg_to_arrays(msg: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(skin (K, 3) int64, rest points (N, 3) float64 m) from a shape_msgs/Mesh; refuses non-finite
    vertices and indices outside the vertices."""
    points = _finite([(p.x, p.y, p.z) for p in msg.vertices] or np.empty((0, 3)), (-1, 3), "Mesh.vertices")
    skin = np.array([t.vertex_indices for t in msg.triangles], dtype=np.int64).reshape(-1, 3)
    return _skin(skin, len(points), "Mesh.triangles"), points


def _skin_marker_without_points(stamp, frame_id: str, colour) -> Marker:
    return Marker(header=_header(stamp, frame_id), ns="liver", id=0, type=Marker.TRIANGLE_LIST, action=Marker.ADD,
                  pose=Pose(orientation=Quaternion(w=1.0)), scale=Vector3(x=1.0, y=1.0, z=1.0), color=_colour(colour))


def _corners(positions, skin) -> np.ndarray:
    """(3K, 3) corners of the skin triangles, in order."""
    points = _finite(positions, (-1, 3), "positions")
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
    from rclpy.serialization import serialize_message

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


# ---------------------------------------------------------------- poses, the local model

def _pose(position, orientation_xyzw, position_name: str) -> Pose:
    x, y, z = _finite(position, (3,), position_name).tolist()
    qx, qy, qz, qw = _unit_quaternion(orientation_xyzw, "orientation_xyzw").tolist()
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _pose_arrays(pose: Pose, name: str) -> tuple[np.ndarray, np.ndarray]:
    position = _finite((pose.position.x, pose.position.y, pose.position.z), (3,), f"{name}.position")
    o = pose.orientation
    return position, _unit_quaternion((o.x, o.y, o.z, o.w), f"{name}.orientation")


def pose_stamped(position, orientation_xyzw, stamp, frame_id: str) -> PoseStamped:
    """PoseStamped of a position (m) and an (x, y, z, w) quaternion (normalised here)."""
    return PoseStamped(header=_header(stamp, frame_id), pose=_pose(position, orientation_xyzw, "position"))


def pose_to_arrays(msg_pose: Pose | PoseStamped) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,) m, unit quaternion (4,) x, y, z, w) of a Pose or PoseStamped; refuses non-finite
    values and a zero quaternion, naming the field."""
    if isinstance(msg_pose, PoseStamped):
        return _pose_arrays(msg_pose.pose, "PoseStamped.pose")
    return _pose_arrays(msg_pose, "Pose")


def pose_stamped_bytes(position, orientation_xyzw, stamp, frame_id: str) -> bytes:
    """Serialized :func:`pose_stamped` (for ``Publisher.publish(bytes)``), without a message object."""
    if type(position) is np.ndarray and position.shape == (3,):
        x, y, z = _finite_floats(tuple(position.tolist()), (3,), "position")
    else:
        x, y, z = _finite(position, (3,), "position").tolist()
    quaternion = _unit_quaternion(orientation_xyzw, "orientation_xyzw").tolist()
    return cdr.encode(*_stamp_parts(stamp), frame_id, (x, y, z, *quaternion))


def pose_from_bytes(data: bytes) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """(position (3,) m, unit quaternion (4,) x, y, z, w, stamp (sec, nanosec)) of a serialized
    PoseStamped; refuses malformed bytes, non-finite values and a zero quaternion, naming the field."""
    sec, nanosec, _, values = cdr.decode(data, cdr.POSE_FIELDS, "PoseStamped")
    position = np.array(_finite_floats(values[:3], (3,), "PoseStamped.pose.position"))
    return position, _unit_quaternion(values[3:], "PoseStamped.pose.orientation"), (sec, nanosec)


def local_model_marker(model: LocalModel, stamp, frame_id: str, lifetime_s: float,
                       patch_size_m: float = 0.04) -> Marker:
    """The physics' local model as the /liver/contact_plane Marker (ns "local_model", id 0), to be trusted
    for `lifetime_s` seconds.

    plane: CUBE at `point`, orientation's z axis = outward `normal`, scale (patch, patch, 1 mm);
    sphere: SPHERE at `centre`, scale = diameter (m) on all axes; not valid: action DELETE.  The model's
    stiffness K, when it has one, rides in `text` as "stiffness_n_per_m=<K>" (STIFFNESS_KEY).
    """
    marker = Marker(header=_header(stamp, frame_id), ns="local_model", id=0,
                    lifetime=_duration(lifetime_s, "lifetime_s"))
    if not model.valid:
        marker.action = Marker.DELETE
        return marker
    if model.kind == "plane":
        patch = positive(patch_size_m, "patch_size_m")
        marker.type = Marker.CUBE
        marker.pose = _pose(model.point, quaternion_from_z_axis(model.normal), "LocalModel.point")
        marker.scale = Vector3(x=patch, y=patch, z=PLANE_THICKNESS_M)
        marker.color = _colour(PLANE_COLOUR)
    else:
        diameter = 2.0 * model.radius_m
        marker.type = Marker.SPHERE
        marker.pose = _pose(model.centre, (0.0, 0.0, 0.0, 1.0), "LocalModel.centre")
        marker.scale = Vector3(x=diameter, y=diameter, z=diameter)
        marker.color = _colour(SPHERE_COLOUR)
    if model.stiffness_n_per_m is not None:
        marker.text = f"{STIFFNESS_KEY}={model.stiffness_n_per_m!r}"
    return marker


#: The key of the local model's stiffness K (N/m) in the Marker's `text` ("key=value").
STIFFNESS_KEY = "stiffness_n_per_m"


def _marker_stiffness(text: str) -> float | None:
    """K (N/m) from a local-model Marker's `text`: None when it carries no STIFFNESS_KEY entry; ValueError
    naming the field for a value that is not a finite number > 0."""
    for entry in text.split():
        key, _, value = entry.partition("=")
        if key == STIFFNESS_KEY:
            try:
                return positive(float(value), f"Marker.text {STIFFNESS_KEY}")
            except ValueError:
                raise ValueError(f"Marker.text {STIFFNESS_KEY} must be a finite number > 0, got {value!r}") from None
    return None


def marker_to_local_model(msg: Marker) -> tuple[LocalModel | None, float]:
    """(local model, lifetime s) from a /liver/contact_plane Marker; the model is None for DELETE and
    DELETEALL (no surface near the tool).

    CUBE → LocalModel.plane(pose.position, normal = the orientation's z axis); SPHERE →
    LocalModel.sphere(pose.position, radius = scale.x / 2); K from `text` (local_model_marker). A lifetime
    of 0 means "forever" to RViz: the caller decides what it trusts.
    """
    lifetime_s = seconds_from_stamp(msg.lifetime)
    if msg.action in (Marker.DELETE, Marker.DELETEALL):
        return None, lifetime_s
    if msg.action != Marker.ADD:
        raise ValueError(f"Marker.action is {msg.action}, expected ADD ({Marker.ADD}), DELETE ({Marker.DELETE}) "
                         f"or DELETEALL ({Marker.DELETEALL})")
    if msg.type not in (Marker.CUBE, Marker.SPHERE):
        raise ValueError(f"Marker.type is {msg.type}, expected CUBE ({Marker.CUBE}) or SPHERE ({Marker.SPHERE})")
    position, orientation = _pose_arrays(msg.pose, "Marker.pose")
    stiffness = _marker_stiffness(msg.text)
    if msg.type == Marker.CUBE:
        return LocalModel.plane(position, quaternion_to_matrix(orientation)[:, 2], stiffness), lifetime_s
    return LocalModel.sphere(position, positive(msg.scale.x, "Marker.scale.x") / 2.0, stiffness), lifetime_s


# ---------------------------------------------------------------- the device map

#: Labels and lengths of the device map's fields in its Float64MultiArray (layout.dim, in this order).
DEVICE_MAP_LAYOUT = (("rotation_xyzw", 4), ("translation_m", 3), ("scale", 1))


def device_map_message(device_map: DeviceMap) -> Float64MultiArray:
    """The map p_liver = scale·R·p_device + t as [qx, qy, qz, qw, tx, ty, tz, scale], its fields labelled in
    layout.dim (TransformStamped has no scale; one message keeps the three consistent)."""
    from liver_sim.geometry.rotations import matrix_to_quaternion

    data = [*matrix_to_quaternion(device_map.rotation).tolist(), *device_map.translation.tolist(), device_map.scale]
    dims = [MultiArrayDimension(label=label, size=size, stride=size) for label, size in DEVICE_MAP_LAYOUT]
    message = Float64MultiArray(data=data)
    message.layout.dim = dims
    return message


def device_map_from_message(msg: Float64MultiArray) -> DeviceMap:
    """The DeviceMap of a :func:`device_map_message`; refuses another layout, non-finite values, a zero
    quaternion and a scale ≤ 0, naming the field."""
    layout = tuple((d.label, d.size) for d in msg.layout.dim)
    if layout != DEVICE_MAP_LAYOUT:
        raise ValueError(f"device map layout must be {list(DEVICE_MAP_LAYOUT)}, got {list(layout)}")
    values = _finite(list(msg.data), (8,), "device map data")
    return DeviceMap(_unit_quaternion(values[:4], "device map rotation_xyzw"), values[4:7],
                     positive(values[7], "device map scale"))


# ---------------------------------------------------------------- forces

def wrench_stamped(force, stamp, frame_id: str, torque=(0.0, 0.0, 0.0)) -> WrenchStamped:
    """WrenchStamped of a force (N) and torque (N·m)."""
    return WrenchStamped(header=_header(stamp, frame_id),
                         wrench=Wrench(force=_vector3_msg(force, "force"), torque=_vector3_msg(torque, "torque")))


def wrench_stamped_bytes(force, stamp, frame_id: str) -> bytes:
    """Serialized :func:`wrench_stamped` with zero torque, without a message object."""
    fx, fy, fz = _finite_floats(tuple(map(float, force)), (3,), "force")
    return cdr.encode(*_stamp_parts(stamp), frame_id, (fx, fy, fz, 0.0, 0.0, 0.0))


def force_message_type(fmt: str) -> type:
    """Message class of the force output format `fmt` (one of FORCE_OUTPUT_FORMATS).

    'omni_feedback' is omni_msgs/OmniFeedback from the user's Geomagic Touch driver workspace, imported
    here; ValueError when that workspace is not sourced or `fmt` is unknown.
    """
    if fmt == "omni_feedback":
        try:
            from omni_msgs.msg import OmniFeedback
        except ImportError as exc:
            raise ValueError("force_output 'omni_feedback' needs omni_msgs (Geomagic Touch ROS 2 driver workspace) "
                             "sourced; it is not installed") from exc
        return OmniFeedback
    if fmt not in _FORCE_TYPES:
        raise ValueError(f"force_output must be one of {FORCE_OUTPUT_FORMATS}, got {fmt!r}")
    return _FORCE_TYPES[fmt]


def force_message(fmt: str, force, stamp, frame_id: str):
    """The force command (N) in format `fmt`: WrenchStamped (torque 0, stamp, frame_id), Wrench (torque 0),
    Vector3, Float64MultiArray data [fx, fy, fz], or OmniFeedback.force (its lock `position` left 0)."""
    msg_type = force_message_type(fmt)
    if fmt == "wrench_stamped":
        return wrench_stamped(force, stamp, frame_id)
    vector = _vector3_msg(force, "force")
    if fmt == "wrench":
        return Wrench(force=vector)
    if fmt == "vector3":
        return vector
    if fmt == "float64_array":
        return Float64MultiArray(data=array.array("d", (vector.x, vector.y, vector.z)))
    return msg_type(force=vector)


def force_message_bytes(fmt: str, force, stamp, frame_id: str) -> bytes:
    """Serialized :func:`force_message`: WrenchStamped without a message object, other formats via rclpy."""
    if fmt == "wrench_stamped":
        return wrench_stamped_bytes(force, stamp, frame_id)
    from rclpy.serialization import serialize_message

    return serialize_message(force_message(fmt, force, stamp, frame_id))


def force_from_bytes(fmt: str, data: bytes) -> np.ndarray:
    """:func:`force_from_message` of a serialized force command: WrenchStamped decoded directly."""
    if fmt == "wrench_stamped":
        return np.array(_finite_floats(cdr.decode(data, cdr.WRENCH_FIELDS, "WrenchStamped")[3][:3], (3,),
                                       "WrenchStamped force"))
    from rclpy.serialization import deserialize_message

    return force_from_message(fmt, deserialize_message(data, force_message_type(fmt)))


def force_from_message(fmt: str, msg) -> np.ndarray:
    """The (3,) force (N) carried by a force output message of format `fmt`; refuses a message of the
    wrong type, a Float64MultiArray without exactly 3 values, and non-finite values."""
    msg_type = force_message_type(fmt)
    if not isinstance(msg, msg_type):
        raise ValueError(f"force_output {fmt!r} carries {msg_type.__name__}, got {type(msg).__name__}")
    if fmt == "float64_array":
        if len(msg.data) != 3:
            raise ValueError(f"Float64MultiArray.data has {len(msg.data)} values, expected 3 (fx, fy, fz)")
        return _finite(msg.data, (3,), "Float64MultiArray.data")
    if fmt == "wrench_stamped":
        vector = msg.wrench.force
    elif fmt == "vector3":
        vector = msg
    else:
        vector = msg.force
    return _finite((vector.x, vector.y, vector.z), (3,), f"{msg_type.__name__} force")
