"""rosbag2 bags through the `rosbags` library: write (MCAP or sqlite3, rosbag2 format 9 with
metadata.yaml), read with checks, and refuse damaged bags with a message naming the bag.

Messages stay serialized (CDR bytes, as the rmw hands them over); message definitions and type
hashes come from rosbags' ROS 2 Jazzy typestore, so `ros2 bag`, rosbags and Foxglove can read them.
No rclpy here.
"""
from __future__ import annotations

import struct
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Iterator

import yaml
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.rosbag2.storage_mcap import McapReader, McapWriter, read_sized
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from rosbags.typesys import Stores, get_typestore

STORAGES = ("mcap", "sqlite3")
#: rosbag2 metadata version written (Jazzy reads 9).
BAG_VERSION = 9


class BagError(ValueError):
    """A bag that cannot be used: the message is `<bag path>: <what is wrong>`."""

    def __init__(self, path, defect: str):
        super().__init__(f"{path}: {defect}")
        self.path = Path(path)


@lru_cache(maxsize=1)
def typestore():
    """rosbags' typestore of ROS 2 Jazzy's message types."""

    return get_typestore(Stores.ROS2_JAZZY)


def canonical_cdr(data: bytes, msgtype: str) -> bytes:
    """The same CDR message with its alignment padding zeroed (rmw serializers leave padding bytes
    uninitialised, so equal messages can differ in bytes): deserialized and serialized again by rosbags."""
    store = typestore()
    return bytes(store.serialize_cdr(store.deserialize_cdr(data, msgtype), msgtype))


@dataclass(frozen=True)
class QosSpec:
    """The QoS a topic was offered with (what `ros2 bag play` replays it with)."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def to_rosbags(self):
        unset = QosTime(0, 0)
        return Qos(QosHistory.KEEP_LAST, self.depth,
                   QosReliability.RELIABLE if self.reliable else QosReliability.BEST_EFFORT,
                   QosDurability.TRANSIENT_LOCAL if self.transient_local else QosDurability.VOLATILE,
                   unset, unset, QosLiveliness.AUTOMATIC, unset, False)


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: topic, type ('pkg/msg/Name'), log time (ns) and CDR bytes."""

    topic: str
    msgtype: str
    timestamp_ns: int
    data: bytes


class BagWriter:
    """A new bag at `path` (a folder that must not exist yet) in `storage` (mcap or sqlite3).

    A topic's connection is added with its first message, so topics that carried nothing are absent.
    `close()` writes the storage's index and metadata.yaml; use as a context manager so that an
    error still leaves a complete bag.
    """

    def __init__(self, path, storage: str = "mcap"):
        self.path = Path(path)
        if storage not in STORAGES:
            raise BagError(self.path, f"storage {storage!r} is not one of {', '.join(STORAGES)}")
        if self.path.exists():
            raise BagError(self.path, "exists already; a bag is never overwritten")
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self._writer = Writer(self.path, version=BAG_VERSION, storage_plugin=plugin)
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            raise BagError(self.path, f"cannot create the bag: {exc}") from None
        self.storage = storage
        self.counts: dict[str, int] = {}
        self._connections = {}

    def write(self, topic: str, msgtype: str, timestamp_ns: int, data: bytes, qos: QosSpec | None = None) -> None:
        """Append one serialized message logged at `timestamp_ns` (ns since the epoch)."""
        connection = self._connections.get(topic)
        if connection is None:
            profiles = [qos.to_rosbags()] if qos is not None else []
            connection = self._writer.add_connection(topic, msgtype, typestore=typestore(),
                                                     offered_qos_profiles=profiles)
            self._connections[topic] = connection
            self.counts[topic] = 0
        self._writer.write(connection, int(timestamp_ns), data)
        self.counts[topic] += 1

    def flush(self) -> None:
        """Put what was written so far into the storage file (an MCAP chunk, an sqlite3 commit), so that a
        recorder killed later leaves it there for `repair_bag`."""

        storage = self._writer.storage
        if isinstance(storage, McapWriter):
            if storage.chunk.bio.tell():
                storage.close_chunk()
            storage.bio.flush()
        else:
            storage.conn.commit()

    def set_custom_data(self, key: str, value) -> None:
        """A key/value pair for metadata.yaml's custom_data (value stored as text)."""
        self._writer.set_custom_data(key, str(value))

    def close(self) -> None:
        """Finish the storage file and write metadata.yaml (idempotent)."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            writer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclass(frozen=True)
class BagInfo:
    """What metadata.yaml says: storage, topics {name: (type, message count)}, start/duration (ns), custom data."""

    path: Path
    storage: str
    topics: dict
    start_ns: int
    duration_ns: int
    custom_data: dict

    @property
    def message_count(self) -> int:
        return sum(count for _, count in self.topics.values())


#: What rosbags (and the storages under it) raise on damaged files.
_READ_ERRORS = (OSError, ValueError, KeyError, IndexError, EOFError, AssertionError, ArithmeticError, MemoryError,
                struct.error)


def _reader_errors():
    return (ReaderError,) + _READ_ERRORS


def _open_reader(path: Path):
    if not path.exists():
        raise BagError(path, "does not exist")
    if not path.is_dir():
        raise BagError(path, "is not a bag folder (a rosbag2 bag is a folder holding metadata.yaml and its storage "
                             "file)")
    if not (path / "metadata.yaml").is_file():
        raise BagError(path, "has no metadata.yaml: not a rosbag2 bag, or its recording was killed before it "
                             "could be closed")
    reader = Reader(path)
    try:
        reader.open()
    except _reader_errors() as exc:
        raise BagError(path, f"unreadable ({type(exc).__name__}: {exc})") from None
    return reader


def bag_info(path) -> BagInfo:
    """The bag's metadata, after checking that its storage opens."""

    path = Path(path)
    reader = _open_reader(path)
    try:
        topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        start_ns, duration_ns = reader.start_time, reader.duration
    finally:
        reader.close()
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return BagInfo(path, str(meta.get("storage_identifier", "")), topics, start_ns, duration_ns,
                   dict(meta.get("custom_data") or {}))


def read_messages(path, topics=None) -> Iterator[BagMessage]:
    """The bag's messages in log-time order (only `topics` if given), checked against metadata.yaml.

    Raises BagError when the storage is damaged or holds fewer messages of a topic than metadata.yaml
    promises (a truncated bag), or when a requested topic is not in the bag.
    """
    path = Path(path)
    reader = _open_reader(path)
    try:
        present = {c.topic for c in reader.connections}
        if topics is not None:
            missing = sorted(set(topics) - present)
            if missing:
                raise BagError(path, f"holds no topic {', '.join(missing)} (it has {', '.join(sorted(present))})")
        connections = [c for c in reader.connections if topics is None or c.topic in topics]
        expected: dict[str, int] = {}
        for c in connections:
            expected[c.topic] = expected.get(c.topic, 0) + c.msgcount
        seen = dict.fromkeys(expected, 0)
        try:
            for connection, timestamp, data in reader.messages(connections=connections):
                seen[connection.topic] += 1
                yield BagMessage(connection.topic, connection.msgtype, timestamp, bytes(data))
        except _reader_errors() as exc:
            raise BagError(path, f"damaged storage after {sum(seen.values())} messages "
                                 f"({type(exc).__name__}: {exc})") from None
        short = {t: (seen[t], n) for t, n in expected.items() if seen[t] != n}
        if short:
            detail = ", ".join(f"{t} has {got} of {want}" for t, (got, want) in sorted(short.items()))
            raise BagError(path, f"truncated or damaged: metadata.yaml promises more messages than stored ({detail})")
    finally:
        reader.close()


def check_bag(path) -> dict[str, int]:
    """Read every message of the bag; return {topic: count}, or BagError."""
    counts: dict[str, int] = {}
    for message in read_messages(path):
        counts[message.topic] = counts.get(message.topic, 0) + 1
    return counts


def _storage_file(path: Path) -> tuple[Path, str]:
    """The bag folder's storage file and its storage, or BagError."""
    if not path.is_dir():
        raise BagError(path, "does not exist" if not path.exists() else "is not a bag folder")
    found = [(f, "mcap" if f.suffix == ".mcap" else "sqlite3") for f in sorted(path.iterdir())
             if f.suffix in (".mcap", ".db3")]
    if len(found) != 1:
        raise BagError(path, f"holds {len(found)} storage files (.mcap or .db3); repair takes a bag of one")
    return found[0]


def _complete_records_end(bio, data_start: int, size: int) -> int:
    """Offset after the last complete MCAP record of the data section (a killed writer leaves a partial one)."""
    position = data_start
    while position + 9 <= size:
        bio.seek(position)
        header = bio.read(9)
        opcode, length = header[0], struct.unpack("<Q", header[1:])[0]
        if opcode in (0x02, 0x0F) or position + 9 + length > size:  # footer, data end, or cut short
            break
        position += 9 + length
    return position


@contextmanager
def _salvaged_mcap(file: Path):
    """(connections, messages) of the complete records of an MCAP file, with or without its summary; the file is
    open while the block runs."""

    reader = McapReader(file)
    with file.open("rb") as reader.bio:
        if reader.bio.read(8) != b"\x89MCAP0\r\n" or reader.bio.read(1) != b"\x01":
            raise ValueError("not an MCAP file")
        read_sized(reader.bio)  # the header record
        reader.data_start = reader.bio.tell()
        reader.data_end = _complete_records_end(reader.bio, reader.data_start, file.stat().st_size)
        reader.meta_scan()
        yield reader.connections, reader.messages_scan(reader.connections)


@contextmanager
def _salvaged_sqlite3(file: Path):
    """(connections, messages) of the committed rows of a rosbag2 sqlite3 file, open while the block runs."""

    reader = Sqlite3Reader(file)
    reader.open()
    try:
        yield reader.connections, reader.messages(reader.connections)
    finally:
        reader.close()


def repair_bag(path, out, progress=print) -> dict[str, int]:
    """Write a complete bag at `out` (new) with every message the storage file of the bag `path` still holds,
    e.g. one whose recorder was killed before it could write its summary and metadata.yaml; `path` is left as
    it is. Returns {topic: count}; BagError when nothing can be read."""

    path, out = Path(path), Path(out)
    file, storage = _storage_file(path)
    if out.exists():
        raise BagError(out, "exists already; a bag is never overwritten")
    try:
        with (_salvaged_mcap if storage == "mcap" else _salvaged_sqlite3)(file) as (connections, messages):
            qos = {}
            for c in connections:
                offered = c.ext.offered_qos_profiles
                qos[c.id] = QosSpec(offered[0].reliability == QosReliability.RELIABLE,
                                    offered[0].durability == QosDurability.TRANSIENT_LOCAL,
                                    offered[0].depth) if offered else None
            with BagWriter(out, storage) as writer:
                for connection, timestamp, data in messages:
                    writer.write(connection.topic, connection.msgtype, timestamp, bytes(data), qos[connection.id])
                writer.set_custom_data("repaired_from", str(path))
                counts = dict(writer.counts)
    except _reader_errors() as exc:
        raise BagError(path, f"cannot be repaired ({type(exc).__name__}: {exc})") from None
    progress(f"wrote {out}: " + (", ".join(f"{t} {n}" for t, n in sorted(counts.items())) or "no messages")
             + f", read from {file}")
    return counts
