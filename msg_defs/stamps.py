"""Times on the wire: builtin_interfaces/Time and Duration of seconds and back, the Header of a stamp."""
from __future__ import annotations

import math

from builtin_interfaces.msg import Duration, Time
from std_msgs.msg import Header

from msg_defs import cdr

_NANO = 1_000_000_000


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


def duration_parts(seconds, name: str) -> tuple[int, int]:
    """(sec, nanosec) of a duration of `seconds` (finite, ≥ 0), or ValueError naming `name`."""
    return _time_parts(seconds, name)


def duration_msg(seconds, name: str) -> Duration:
    """builtin_interfaces/Duration of `seconds` (finite, ≥ 0), or ValueError naming `name`."""
    sec, nanosec = duration_parts(seconds, name)
    return Duration(sec=sec, nanosec=nanosec)


def stamp_parts(stamp) -> tuple[int, int]:
    """(sec, nanosec) of a builtin_interfaces/Time, a (sec, nanosec) pair or a time in seconds."""
    if isinstance(stamp, Time):
        return stamp.sec, stamp.nanosec
    if isinstance(stamp, tuple):
        return stamp
    return _time_parts(stamp, "stamp")


def header_msg(stamp, frame_id: str) -> Header:
    """std_msgs/Header of a stamp (as :func:`stamp_parts` takes it) and a frame id."""
    sec, nanosec = stamp_parts(stamp)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)
