"""Taking a serialized message with the publisher's GID and publication sequence number; a publisher's own GID.

rclpy 7.1 (Jazzy) hands a subscription's message info over as a dict with `source_timestamp`,
`received_timestamp`, `publication_sequence_number` and `reception_sequence_number`, but without
`publisher_gid`; Fast DDS numbers publications per writer (1, 2, …), so a gap can only be counted
per writer. `SerializedTake` calls `rcl_take_serialized_message` of the rcl library rclpy itself
loaded, with the Jazzy layout of `rmw_message_info_t` (rmw/types.h, RMW_GID_STORAGE_SIZE 16).
rclpy has no publisher GID either: :func:`publisher_gid` asks the loaded rmw implementation
(`rmw_get_gid_for_publisher`). A GID is the one the graph gives the writer
(`get_publishers_info_by_topic(...)[i].endpoint_gid`), so a sample names the node that wrote it.
"""
from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from functools import lru_cache

from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: F401 (loads rcl and rcutils)

#: rmw/types.h (Jazzy): bytes of a GID.
GID_SIZE = 16
#: rcl/types.h: a take that found no message.
RCL_RET_OK = 0
RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401


class _Gid(ctypes.Structure):
    _fields_ = [("implementation_identifier", ctypes.c_char_p), ("data", ctypes.c_uint8 * GID_SIZE)]


class _MessageInfo(ctypes.Structure):
    _fields_ = [("source_timestamp", ctypes.c_int64), ("received_timestamp", ctypes.c_int64),
                ("publication_sequence_number", ctypes.c_uint64), ("reception_sequence_number", ctypes.c_uint64),
                ("publisher_gid", _Gid), ("from_intra_process", ctypes.c_bool)]


class _Allocator(ctypes.Structure):
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p), ("reallocate", ctypes.c_void_p),
                ("zero_allocate", ctypes.c_void_p), ("state", ctypes.c_void_p)]


class _Uint8Array(ctypes.Structure):  # rmw_serialized_message_t
    _fields_ = [("buffer", ctypes.POINTER(ctypes.c_uint8)), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", _Allocator)]


def _loaded_library(name: str) -> ctypes.CDLL:
    """The shared library `name` (e.g. 'librcl.so') as this process already mapped it (rclpy loads it)."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            path = line.split()[-1]
            if os.path.basename(path).split(".so")[0] == name.split(".so")[0] and ".so" in path:
                return ctypes.CDLL(path)
    raise RuntimeError(f"{name} is not loaded: import rclpy first")


def _loaded_symbol(symbol: str):
    """`symbol` from whichever shared library this process mapped exports it (the rmw implementation)."""
    with open("/proc/self/maps") as maps:
        paths = sorted({line.split()[-1] for line in maps if ".so" in line and "rmw" in line})
    for path in paths:
        function = getattr(ctypes.CDLL(path), symbol, None)
        if function is not None:
            return function
    raise RuntimeError(f"no loaded rmw library exports {symbol}: import rclpy first")


@lru_cache(maxsize=1)
def _gid_functions():
    rcl = _loaded_library("librcl.so")
    handle = rcl.rcl_publisher_get_rmw_handle
    handle.argtypes, handle.restype = [ctypes.c_void_p], ctypes.c_void_p
    gid = _loaded_symbol("rmw_get_gid_for_publisher")
    gid.argtypes, gid.restype = [ctypes.c_void_p, ctypes.POINTER(_Gid)], ctypes.c_int
    return handle, gid


def publisher_gid(publisher) -> bytes:
    """The GID (GID_SIZE bytes) of an rclpy publisher, as the graph and a sample's message info name it."""
    handle, get_gid = _gid_functions()
    gid = _Gid()
    with publisher.handle:
        status = get_gid(handle(publisher.handle.pointer), ctypes.byref(gid))
    if status != RCL_RET_OK:
        raise RuntimeError(f"rmw_get_gid_for_publisher failed ({status}) for {publisher.topic_name}")
    return bytes(gid.data)


def endpoint_gid(info) -> bytes:
    """The GID of a graph endpoint (rclpy TopicEndpointInfo), as :func:`publisher_gid` gives it."""
    return bytes(info.endpoint_gid)[:GID_SIZE]


@lru_cache(maxsize=1)
def _functions():
    rcl, rcutils = _loaded_library("librcl.so"), _loaded_library("librcutils.so")
    take = rcl.rcl_take_serialized_message
    take.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Uint8Array), ctypes.POINTER(_MessageInfo), ctypes.c_void_p]
    take.restype = ctypes.c_int
    allocator = rcutils.rcutils_get_default_allocator
    allocator.argtypes, allocator.restype = [], _Allocator
    init = rcutils.rcutils_uint8_array_init
    init.argtypes = [ctypes.POINTER(_Uint8Array), ctypes.c_size_t, ctypes.POINTER(_Allocator)]
    init.restype = ctypes.c_int
    fini = rcutils.rcutils_uint8_array_fini
    fini.argtypes, fini.restype = [ctypes.POINTER(_Uint8Array)], ctypes.c_int
    error = rcutils.rcutils_get_error_string
    error.argtypes, error.restype = [], ctypes.c_char * 1024
    reset = rcutils.rcutils_reset_error
    reset.argtypes, reset.restype = [], None
    return take, allocator, init, fini, error, reset


@dataclass(frozen=True)
class Taken:
    """One serialized message and what DDS says of it: publisher GID (16 bytes), its publication
    sequence number, source and reception timestamps (system clock ns), and its `size` (bytes); `data` is empty
    when `size` is over the take's bound (the message was not copied into Python)."""

    data: bytes
    gid: bytes
    sequence: int
    source_ns: int
    received_ns: int
    size: int


class SerializedTake:
    """Takes the serialized messages of one rclpy subscription (made with raw=True), with their info; a message
    longer than `max_bytes` is taken with empty `data` (its bytes are never copied into a Python object)."""

    def __init__(self, subscription, initial_capacity: int = 4096, max_bytes: int | None = None):
        self._take, allocator, init, self._fini, self._error, self._reset = _functions()
        self.subscription = subscription
        self._message = _Uint8Array()
        self._allocator = allocator()
        if init(ctypes.byref(self._message), initial_capacity, ctypes.byref(self._allocator)) != RCL_RET_OK:
            raise MemoryError("rcutils_uint8_array_init failed")
        self._info = _MessageInfo()
        self.max_bytes = max_bytes

    def __call__(self) -> Taken | None:
        """The next waiting message, or None."""
        with self.subscription.handle:
            status = self._take(self.subscription.handle.pointer, ctypes.byref(self._message),
                                ctypes.byref(self._info), None)
        if status == RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            return None
        if status != RCL_RET_OK:
            detail = self._error().value.decode(errors="replace")
            self._reset()
            raise RuntimeError(f"taking a message of {self.subscription.topic_name} failed ({status}: {detail})")
        info, size = self._info, self._message.buffer_length
        data = b"" if self.max_bytes is not None and size > self.max_bytes else ctypes.string_at(
            self._message.buffer, size)
        return Taken(data, bytes(info.publisher_gid.data), int(info.publication_sequence_number),
                     int(info.source_timestamp), int(info.received_timestamp), size)

    def close(self) -> None:
        if self._message.buffer:
            self._fini(ctypes.byref(self._message))
