"""The device → liver map (liver_sim.base.geometry.device_map.DeviceMap) as a labelled Float64MultiArray
(/tool/device_map), and back."""
from __future__ import annotations

from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from liver_sim.base.checks import positive
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.geometry.rotations import matrix_to_quaternion
from msg_defs.finite import finite_array, unit_quaternion

#: Labels and lengths of the device map's fields in its Float64MultiArray (layout.dim, in this order).
DEVICE_MAP_LAYOUT = (("rotation_xyzw", 4), ("translation_m", 3), ("scale", 1))


def device_map_message(device_map: DeviceMap) -> Float64MultiArray:
    """The map p_liver = scale·R·p_device + t as [qx, qy, qz, qw, tx, ty, tz, scale], its fields labelled in
    layout.dim (TransformStamped has no scale; one message keeps the three consistent)."""

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
    values = finite_array(list(msg.data), (8,), "device map data")
    return DeviceMap(unit_quaternion(values[:4], "device map rotation_xyzw"), values[4:7],
                     positive(values[7], "device map scale"))
