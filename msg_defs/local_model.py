"""The local model (liver_sim.base.local_model.LocalModel) as the /liver/contact_plane Marker, and back (from the
message or from its bytes)."""
from __future__ import annotations

import re

import numpy as np
from rclpy.serialization import deserialize_message
from visualization_msgs.msg import Marker

from liver_sim.base.checks import non_negative, positive
from liver_sim.base.geometry.rotations import quaternion_from_z_axis, quaternion_to_matrix
from liver_sim.base.local_model import LocalModel
from msg_defs import cdr
from msg_defs.finite import finite_floats, unit_quaternion
from msg_defs.stamps import duration_parts, seconds_from_stamp, stamp_parts

PLANE_COLOUR = (0.2, 0.8, 0.3, 0.5)
SPHERE_COLOUR = (0.2, 0.5, 0.9, 0.3)
#: Thickness (m) of the CUBE that draws a plane local model.
PLANE_THICKNESS_M = 0.001
#: The key of the local model's stiffness K (N/m) in the Marker's `text` ("key=value").
STIFFNESS_KEY = "stiffness_n_per_m"
#: The key of the model's depth (m) at the physics' pose (LocalModel.depth_m) in the Marker's `text`, beside K.
DEPTH_KEY = "depth_m"
#: The first STIFFNESS_KEY entry among the whitespace-separated entries of `text`, found without splitting it.
_STIFFNESS_ENTRY = re.compile(rf"(?:^|\s){STIFFNESS_KEY}=(\S*)")
#: The first DEPTH_KEY entry, found the same way.
_DEPTH_ENTRY = re.compile(rf"(?:^|\s){DEPTH_KEY}=(\S*)")


def local_model_marker(model: LocalModel, stamp, frame_id: str, lifetime_s: float,
                       patch_size_m: float = 0.04) -> Marker:
    """The physics' local model as the /liver/contact_plane Marker (ns "local_model", id 0), to be trusted
    for `lifetime_s` seconds: :func:`local_model_marker_bytes` read back, one encoding for the wire and its readers.

    plane: CUBE at `point`, orientation's z axis = outward `normal`, scale (patch, patch, 1 mm);
    sphere: SPHERE at `centre`, scale = diameter (m) on all axes; not valid: action DELETE.  The model's
    stiffness K, when it has one, rides in `text` with its depth d at the physics' pose (m, LocalModel.depth_m) as
    "stiffness_n_per_m=<K> depth_m=<d>" (STIFFNESS_KEY, DEPTH_KEY): K·d is the physics' force, which a bridge that
    caps K needs to render it at that pose.
    """
    return deserialize_message(local_model_marker_bytes(model, stamp, frame_id, lifetime_s, patch_size_m), Marker)


def local_model_marker_bytes(model: LocalModel, stamp, frame_id: str, lifetime_s: float,
                             patch_size_m: float = 0.04) -> bytes:
    """The serialized local-model Marker (:func:`local_model_marker`, for ``Publisher.publish(bytes)``), without a
    message object: what rmw_fastrtps writes for it, its padding zeroed."""
    sec, nanosec = stamp_parts(stamp)
    lifetime = duration_parts(lifetime_s, "lifetime_s")
    if not model.valid:
        return cdr.marker_bytes((sec, nanosec), frame_id, "local_model", 0, Marker.ARROW, Marker.DELETE,
                                (0.0,) * 6 + (1.0,), (0.0,) * 3, (0.0,) * 4, lifetime, "")
    if model.kind == "plane":
        patch = positive(patch_size_m, "patch_size_m")
        position = finite_floats(tuple(model.point.tolist()), (3,), "LocalModel.point")
        orientation = quaternion_from_z_axis(model.normal.tolist())
        kind, scale, colour = Marker.CUBE, (patch, patch, PLANE_THICKNESS_M), PLANE_COLOUR
    else:
        diameter = 2.0 * model.radius_m
        position = finite_floats(tuple(model.centre.tolist()), (3,), "LocalModel.centre")
        orientation, kind, scale, colour = (0.0, 0.0, 0.0, 1.0), Marker.SPHERE, (diameter,) * 3, SPHERE_COLOUR
    text = "" if model.stiffness_n_per_m is None else \
        f"{STIFFNESS_KEY}={model.stiffness_n_per_m!r} {DEPTH_KEY}={non_negative(model.depth_m, 'LocalModel.depth_m')!r}"
    return cdr.marker_bytes((sec, nanosec), frame_id, "local_model", 0, kind, Marker.ADD, (*position, *orientation),
                            scale, colour, lifetime, text)


def _marker_entry(text: str, entry: re.Pattern, key: str, check, bound: str, missing):
    """The number of the first `key` entry (found by `entry`) of a local-model Marker's `text`, through `check` (a
    liver_sim.base.checks function); `missing` when there is none; ValueError naming the field for a value that is
    not a finite number `bound`."""
    found = entry.search(text)
    if found is None:
        return missing
    value = found.group(1)
    try:
        return check(float(value), f"Marker.text {key}")
    except ValueError:
        raise ValueError(f"Marker.text {key} must be a finite number {bound}, got {value[:40]!r}") from None


def _marker_stiffness(text: str) -> float | None:
    """K (N/m) from a local-model Marker's `text`: None when it carries no STIFFNESS_KEY entry; ValueError
    naming the field for a value that is not a finite number > 0."""
    return _marker_entry(text, _STIFFNESS_ENTRY, STIFFNESS_KEY, positive, "> 0", None)


def _marker_depth(text: str) -> float:
    """The depth (m) at the physics' pose from a local-model Marker's `text`: 0 when it carries no DEPTH_KEY entry
    (a Marker from before the entry, read as :meth:`LocalModel.plane` and :meth:`LocalModel.sphere` make it: no
    depth seen); ValueError naming the field for a value that is not a finite number >= 0."""
    return _marker_entry(text, _DEPTH_ENTRY, DEPTH_KEY, non_negative, ">= 0", 0.0)


def marker_to_local_model(msg: Marker) -> tuple[LocalModel | None, float]:
    """(local model, lifetime s) from a /liver/contact_plane Marker; the model is None for DELETE and
    DELETEALL (no surface near the tool).

    CUBE → LocalModel.plane(pose.position, normal = the orientation's z axis); SPHERE →
    LocalModel.sphere(pose.position, radius = scale.x / 2); K and depth_m from `text` (local_model_marker; no
    depth_m entry: 0). A lifetime
    of 0 means "forever" to RViz: the caller decides what it trusts.
    """
    p, o = msg.pose.position, msg.pose.orientation
    return _local_model(msg.action, msg.type, (p.x, p.y, p.z), (o.x, o.y, o.z, o.w), msg.scale.x, msg.text,
                        seconds_from_stamp(msg.lifetime))


def local_model_from_bytes(data: bytes) -> tuple[LocalModel | None, float]:
    """:func:`marker_to_local_model` of a serialized Marker (a raw subscription), without a message object;
    malformed bytes are refused like bad fields, with a ValueError naming the field."""
    fields = cdr.marker_fields(data)
    sec, nanosec = fields["lifetime"]
    pose = fields["pose"]
    return _local_model(fields["action"], fields["type"], pose[:3], pose[3:], fields["scale"][0], fields["text"],
                        sec + nanosec * 1e-9)


def _local_model(action: int, marker_type: int, position, orientation, scale_x: float, text: str,
                 lifetime_s: float) -> tuple[LocalModel | None, float]:
    """The checks and the model shared by both readers: the Marker's fields as plain values."""
    if action in (Marker.DELETE, Marker.DELETEALL):
        return None, lifetime_s
    if action != Marker.ADD:
        raise ValueError(f"Marker.action is {action}, expected ADD ({Marker.ADD}), DELETE ({Marker.DELETE}) "
                         f"or DELETEALL ({Marker.DELETEALL})")
    if marker_type not in (Marker.CUBE, Marker.SPHERE):
        raise ValueError(f"Marker.type is {marker_type}, expected CUBE ({Marker.CUBE}) or SPHERE ({Marker.SPHERE})")
    position = np.array(finite_floats(tuple(position), (3,), "Marker.pose.position"))
    orientation = unit_quaternion(tuple(orientation), "Marker.pose.orientation")
    stiffness, depth = _marker_stiffness(text), _marker_depth(text)
    if marker_type == Marker.CUBE:
        model = LocalModel.plane(position, quaternion_to_matrix(orientation)[:, 2], stiffness)
    else:
        model = LocalModel.sphere(position, positive(scale_x, "Marker.scale.x") / 2.0, stiffness)
    return (model if depth == 0.0 else LocalModel.derived(model, depth_m=depth)), lifetime_s
