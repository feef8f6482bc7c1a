"""A Foxglove WebSocket client for the tests, as the Foxglove app speaks to a server (subprotocol foxglove.sdk.v1,
with foxglove.websocket.v1 as fallback): it reads the advertised channels, subscribes, and takes message data.
Protobuf payloads are read with a small wire-format reader, the field numbers taken from the schema the server
advertises (a FileDescriptorSet), so no protobuf package is needed."""
from __future__ import annotations

import asyncio
import base64
import json
import struct
import threading
import time

import websockets

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01
#: The channels `liver-sim view` serves, the scenes first.
VIEW_TOPICS = ("/liver/scene", "/liver/forces", "/liver/diagnostics")


def _varint(data: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, i


def fields(data: bytes) -> list[tuple[int, int, object]]:
    """(field number, wire type, value) of each field of a protobuf message: varints as int, length-delimited as
    bytes, fixed64/fixed32 as bytes."""
    out, i = [], 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value, i = data[i:i + 8], i + 8
        elif wire == 2:
            length, i = _varint(data, i)
            value, i = data[i:i + length], i + length
        elif wire == 5:
            value, i = data[i:i + 4], i + 4
        else:
            raise ValueError(f"unsupported wire type {wire}")
        out.append((number, wire, value))
    return out


def field_numbers(descriptor_set: bytes, what: int = 3) -> dict[str, dict[str, int]]:
    """{message name: {field name: number}} of a FileDescriptorSet (file=1; FileDescriptorProto.message_type=4;
    DescriptorProto name=1, field=2; FieldDescriptorProto name=1, number=3, type=5); `what=5`: each field's type
    instead of its number."""
    messages = {}
    for number, _, file in fields(descriptor_set):
        if number != 1:
            continue
        for number, _, message in fields(file):
            if number != 4:
                continue
            parts = fields(message)
            name = next(v.decode() for n, _, v in parts if n == 1)
            numbers = {}
            for n, _, field in parts:
                if n == 2:
                    described = fields(field)
                    numbers[next(v.decode() for k, _, v in described if k == 1)] = next(
                        v for k, _, v in described if k == what)
            messages[name] = numbers
    return messages


#: FieldDescriptorProto.Type of the fixed-width 32-bit integers, packed four bytes each.
FIXED32_TYPES = (7, 15)


def packed_count(data: bytes, field_type: int) -> int:
    """How many values a packed repeated integer field holds, by its descriptor type."""
    return len(data) // 4 if field_type in FIXED32_TYPES else len(packed_uint32(data))


def packed_uint32(data: bytes) -> list[int]:
    values, i = [], 0
    while i < len(data):
        value, i = _varint(data, i)
        values.append(value)
    return values


async def _session(url: str, topics: list[str], seconds: float, subprotocols) -> tuple[dict, dict, dict]:
    async with websockets.connect(url, subprotocols=subprotocols, max_size=None) as socket:
        channels, received, info = {}, {topic: [] for topic in topics}, {}
        subscribed = {}
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(socket.recv(), timeout=max(0.01, deadline - time.monotonic()))
            except asyncio.TimeoutError:
                break
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "serverInfo":
                    info = message
                elif message["op"] == "advertise":
                    for channel in message["channels"]:
                        channels[channel["topic"]] = channel
                        if channel["topic"] in topics and channel["topic"] not in subscribed.values():
                            sid = len(subscribed) + 1
                            subscribed[sid] = channel["topic"]
                            await socket.send(json.dumps({"op": "subscribe",
                                                          "subscriptions": [{"id": sid, "channelId": channel["id"]}]}))
            elif frame[0] == MESSAGE_DATA:
                sid, log_time = struct.unpack_from("<IQ", frame, 1)
                received[subscribed[sid]].append((time.monotonic(), log_time, frame[13:]))
        info["subprotocol"] = socket.subprotocol
        return info, channels, received


def listen(port: int, topics: list[str], seconds: float, host: str = "127.0.0.1"):
    """(serverInfo, {topic: advertised channel}, {topic: [(arrival monotonic s, log time ns, payload bytes)]}) of a
    session of `seconds` with the server at host:port, subscribed to `topics`."""
    return asyncio.run(_session(f"ws://{host}:{port}", topics, seconds, SUBPROTOCOLS))


def schema_bytes(channel: dict) -> bytes:
    """The channel's schema as bytes (base64 for binary schema encodings such as protobuf)."""
    schema = channel["schema"]
    return base64.b64decode(schema) if channel.get("schemaEncoding") == "protobuf" else schema.encode()


class Watcher:
    """A client that keeps connecting to host:port in a thread of its own, each time for `seconds`, until a session
    brings more than `enough` messages of `topics[0]` or stop() is called; `session` is then the (serverInfo,
    channels, received) of `listen` with the most of them (None if it never connected)."""

    def __init__(self, port: int, topics: list[str], enough: int = 10, seconds: float = 3.0):
        self.session = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(port, topics, enough, seconds), daemon=True)
        self._thread.start()

    def _run(self, port, topics, enough, seconds):
        while not self._stop.is_set():
            try:  # until the view serves and the physics publishes (scenes start with the surface and the nodes)
                session = listen(port, topics, seconds)
            except OSError:  # not serving yet
                time.sleep(0.2)
                continue
            count = len(session[2].get(topics[0], ()))
            if self.session is None or count > len(self.session[2].get(topics[0], ())):
                self.session = session
            if count > enough:
                return

    def stop(self, timeout_s: float = 10.0):
        """Stop connecting, wait for the session under way, and return `session`."""
        self._stop.set()
        self._thread.join(timeout_s)
        return self.session
