"""Serialized (CDR) PoseStamped and WrenchStamped without message objects, for the 1 kHz topics, and a
local-model Marker's fields, read and written.

Building a rosidl Python message and converting it costs tens of microseconds per message; the
1 kHz loops instead publish and take these two fixed-layout messages as bytes (`Publisher.publish(bytes)`,
raw subscriptions). The bridge's loop reads the 150 Hz /liver/contact_plane Marker from its bytes too
(:func:`marker_fields`), and the physics writes it as bytes (:func:`marker_bytes`): a message object costs
more than the rest of the tick.
Layout (XCDR1, as rmw_fastrtps writes it): a 4-byte encapsulation header
(0x00 0x01 = little-endian, 0x00 0x00 = big-endian, then 2 option bytes), then, aligned relative to
the byte after the header: stamp.sec int32, stamp.nanosec uint32, frame_id as uint32 length
(with its NUL) + characters + NUL, padding to 8, then the float64 payload
(PoseStamped: position x y z, orientation x y z w; WrenchStamped: force x y z, torque x y z).

Readers refuse truncated or inconsistent bytes with a ValueError naming the field, and messages longer than
MAX_BYTES of their type before reading anything (decoding a long Marker would hold up the 1 kHz loop);
checking that the numbers are finite is the caller's (msg_defs.poses, msg_defs.forces).
"""
from __future__ import annotations

import functools
import struct

_LITTLE = b"\x00\x01\x00\x00"
_ENDIAN = {b"\x00\x01": "<", b"\x00\x00": ">"}
_STAMP_AND_LENGTH = {e: struct.Struct(e + "iII") for e in "<>"}
POSE_FIELDS = 7
WRENCH_FIELDS = 6
_PAYLOAD = {(e, n): struct.Struct(f"{e}{n}d") for e in "<>" for n in (POSE_FIELDS, WRENCH_FIELDS)}
#: The longest serialized message (bytes) a loop reads, by type: a stamped pose or wrench with a frame_id of
#: up to about 900 characters; a local-model Marker with short strings and empty sequences (its text carries
#: one key=value, msg_defs.local_model).
MAX_BYTES = {"PoseStamped": 1024, "WrenchStamped": 1024, "Marker": 4096}


def check_size(data: bytes, type_name: str) -> None:
    """ValueError when `data` is longer than MAX_BYTES[type_name]."""
    if len(data) > MAX_BYTES[type_name]:
        raise ValueError(f"{type_name}: {len(data)} bytes, more than the {MAX_BYTES[type_name]} a {type_name} "
                         f"read by a loop may have (msg_defs.cdr.MAX_BYTES)")


def encode(sec: int, nanosec: int, frame_id: str, values) -> bytes:
    """Little-endian CDR of a Header (sec, nanosec, frame_id) followed by 7 (pose) or 6 (wrench) float64."""
    frame = frame_id.encode()
    head = _STAMP_AND_LENGTH["<"].pack(sec, nanosec, len(frame) + 1)
    padding = b"\x00" * (-(len(head) + len(frame) + 1) % 8)
    return b"".join((_LITTLE, head, frame, b"\x00", padding, _PAYLOAD["<", len(values)].pack(*values)))


def _header(data: bytes, type_name: str) -> tuple[str, int, int, int]:
    """(struct endianness, stamp sec, stamp nanosec, frame_id length) of a serialized stamped message."""
    check_size(data, type_name)
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


@functools.lru_cache(maxsize=None)
def _layout(endian: str, count: int, code: str) -> struct.Struct:
    return struct.Struct(f"{endian}{count}{code}")


class _Cursor:
    """Reads a serialized message field by field: XCDR1 alignment counted from the byte after the 4-byte
    encapsulation header; a field that runs past the end is a ValueError naming it."""

    def __init__(self, data: bytes, type_name: str):
        check_size(data, type_name)
        self.endian = _ENDIAN.get(bytes(data[:2]))
        if self.endian is None or len(data) < 8:
            raise ValueError(f"{type_name}: not a CDR message ({len(data)} bytes, header {bytes(data[:4]).hex()})")
        self.data, self.type_name, self.offset = data, type_name, 4

    def _take(self, size: int, alignment: int, field: str) -> int:
        start = self.offset + (-(self.offset - 4) % alignment)
        if start + size > len(self.data):
            raise ValueError(f"{self.type_name}.{field}: truncated at byte {start} of {len(self.data)}")
        self.offset = start + size
        return start

    def values(self, code: str, count: int, field: str) -> tuple:
        """`count` numbers of struct `code` ('i', 'I', 'f', 'd', '?')."""
        layout = _layout(self.endian, count, code)
        return layout.unpack_from(self.data, self._take(layout.size, struct.calcsize(code), field))

    def string(self, field: str) -> str:
        (length,) = self.values("I", 1, field)
        start = self._take(length, 1, field)
        if length < 1 or self.data[start + length - 1] != 0:
            raise ValueError(f"{self.type_name}.{field}: bad string length {length}")
        return bytes(self.data[start:start + length - 1]).decode(errors="replace")

    def skip_sequence(self, element_size: int, alignment: int, field: str) -> None:
        (count,) = self.values("I", 1, field)
        if count:
            self._take(count * element_size, alignment, field)


def marker_fields(data: bytes) -> dict:
    """The fields of a serialized visualization_msgs/Marker (Jazzy) a local model is read from: `stamp` (sec,
    nanosec), `frame_id`, `ns`, `id`, `type`, `action`, `pose` (position x y z, orientation x y z w),
    `scale` (x, y, z), `lifetime` (sec, nanosec), `text`; the fields between them are checked and skipped."""
    read = _Cursor(data, "Marker")
    fields = {"stamp": read.values("i", 1, "header.stamp.sec") + read.values("I", 1, "header.stamp.nanosec"),
              "frame_id": read.string("header.frame_id"), "ns": read.string("ns")}
    fields["id"], fields["type"], fields["action"] = read.values("i", 3, "id, type, action")
    fields["pose"] = read.values("d", 7, "pose")
    fields["scale"] = read.values("d", 3, "scale")
    read.values("f", 4, "color")
    fields["lifetime"] = read.values("i", 1, "lifetime.sec") + read.values("I", 1, "lifetime.nanosec")
    read.values("?", 1, "frame_locked")
    read.skip_sequence(24, 8, "points")
    read.skip_sequence(16, 4, "colors")
    read.string("texture_resource")
    read.values("i", 2, "texture.header.stamp")
    read.string("texture.header.frame_id")
    read.string("texture.format")
    read.skip_sequence(1, 1, "texture.data")
    read.skip_sequence(8, 4, "uv_coordinates")
    fields["text"] = read.string("text")
    return fields


class _Writer:
    """Writes a little-endian serialized message field by field, with XCDR1 alignment counted from the byte after
    the 4-byte encapsulation header (the mirror of _Cursor)."""

    def __init__(self):
        self.parts = [_LITTLE]
        self.offset = 0  # bytes written after the encapsulation header

    def _align(self, alignment: int) -> None:
        padding = -self.offset % alignment
        if padding:
            self.parts.append(b"\x00" * padding)
            self.offset += padding

    def values(self, code: str, values) -> None:
        layout = _layout("<", len(values), code)
        self._align(struct.calcsize(code))
        self.parts.append(layout.pack(*values))
        self.offset += layout.size

    def string(self, text: str) -> None:
        encoded = text.encode() + b"\x00"
        self.values("I", (len(encoded),))
        self.parts.append(encoded)
        self.offset += len(encoded)

    def empty_sequence(self) -> None:
        self.values("I", (0,))

    def result(self) -> bytes:
        return b"".join(self.parts)


def marker_bytes(stamp: tuple[int, int], frame_id: str, ns: str, marker_id: int, marker_type: int, action: int,
                 pose, scale, colour, lifetime: tuple[int, int], text: str) -> bytes:
    """A serialized visualization_msgs/Marker (Jazzy) with these fields, no points, colours, texture or mesh: the
    bytes rmw_fastrtps writes for the same message (a test holds them equal)."""
    write = _Writer()
    write.values("i", stamp[:1])
    write.values("I", stamp[1:])
    write.string(frame_id)
    write.string(ns)
    write.values("i", (marker_id, marker_type, action))
    write.values("d", tuple(pose))
    write.values("d", tuple(scale))
    write.values("f", tuple(colour))
    write.values("i", lifetime[:1])
    write.values("I", lifetime[1:])
    write.values("?", (False,))            # frame_locked
    write.empty_sequence()                 # points
    write.empty_sequence()                 # colors
    write.string("")                       # texture_resource
    write.values("i", (0,))                # texture.header.stamp
    write.values("I", (0,))
    write.string("")                       # texture.header.frame_id
    write.string("")                       # texture.format
    write.empty_sequence()                 # texture.data
    write.empty_sequence()                 # uv_coordinates
    write.string(text)
    write.string("")                       # mesh_resource
    write.string("")                       # mesh_file.filename
    write.empty_sequence()                 # mesh_file.data
    write.values("?", (False,))            # mesh_use_embedded_materials
    return write.result()
