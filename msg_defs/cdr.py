"""Serialized (CDR) PoseStamped and WrenchStamped without message objects, for the 1 kHz topics.

Building a rosidl Python message and converting it costs tens of microseconds per message; the
1 kHz loops instead publish and take these two fixed-layout messages as bytes (`Publisher.publish(bytes)`,
raw subscriptions). Layout (XCDR1, as rmw_fastrtps writes it): a 4-byte encapsulation header
(0x00 0x01 = little-endian, 0x00 0x00 = big-endian, then 2 option bytes), then, aligned relative to
the byte after the header: stamp.sec int32, stamp.nanosec uint32, frame_id as uint32 length
(with its NUL) + characters + NUL, padding to 8, then the float64 payload
(PoseStamped: position x y z, orientation x y z w; WrenchStamped: force x y z, torque x y z).

Readers refuse truncated or inconsistent bytes with a ValueError naming the field; checking that
the numbers are finite is the caller's (msg_defs.poses, msg_defs.forces).
"""
from __future__ import annotations

import struct

_LITTLE = b"\x00\x01\x00\x00"
_ENDIAN = {b"\x00\x01": "<", b"\x00\x00": ">"}
_STAMP_AND_LENGTH = {e: struct.Struct(e + "iII") for e in "<>"}
POSE_FIELDS = 7
WRENCH_FIELDS = 6
_PAYLOAD = {(e, n): struct.Struct(f"{e}{n}d") for e in "<>" for n in (POSE_FIELDS, WRENCH_FIELDS)}


def encode(sec: int, nanosec: int, frame_id: str, values) -> bytes:
    """Little-endian CDR of a Header (sec, nanosec, frame_id) followed by 7 (pose) or 6 (wrench) float64."""
    frame = frame_id.encode()
    head = _STAMP_AND_LENGTH["<"].pack(sec, nanosec, len(frame) + 1)
    padding = b"\x00" * (-(len(head) + len(frame) + 1) % 8)
    return b"".join((_LITTLE, head, frame, b"\x00", padding, _PAYLOAD["<", len(values)].pack(*values)))


def _header(data: bytes, type_name: str) -> tuple[str, int, int, int]:
    """(struct endianness, stamp sec, stamp nanosec, frame_id length) of a serialized stamped message."""
    endian = _ENDIAN.get(bytes(data[:2]))
    if endian is None or len(data) < 16:
        raise ValueError(f"{type_name}: not a CDR message ({len(data)} bytes, header {bytes(data[:4]).hex()})")
    return (endian, *_STAMP_AND_LENGTH[endian].unpack_from(data, 4))


def stamp(data: bytes, type_name: str) -> tuple[int, int]:
    """(sec, nanosec) of the header stamp of any serialized message that begins with a std_msgs/Header."""
    return _header(data, type_name)[1:3]


def decode(data: bytes, fields: int, type_name: str) -> tuple[int, int, str, tuple]:
    """(sec, nanosec, frame_id, `fields` float64 values) of a serialized Header-plus-doubles message."""
    endian, sec, nanosec, length = _header(data, type_name)
    end = 16 + length
    if length < 1 or end > len(data) or data[end - 1] != 0:
        raise ValueError(f"{type_name}.header.frame_id: bad string length {length} in {len(data)} bytes")
    start = end + (-(end - 4) % 8)
    payload = _PAYLOAD[endian, fields]
    if len(data) < start + payload.size:
        raise ValueError(f"{type_name}: truncated, {len(data)} bytes, expected {start + payload.size}")
    frame_id = bytes(data[16:end - 1]).decode(errors="replace")
    return sec, nanosec, frame_id, payload.unpack_from(data, start)
