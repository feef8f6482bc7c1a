"""Counting lost messages from publication sequence numbers (no ROS here).

DDS numbers every publication of a writer 1, 2, 3, …; a reader that receives k and then k + n from the
same writer missed n − 1 messages. Writers already publishing when a recording began (shown in the graph
then, or whose first received message was published before it: a transient-local history that reached a
recorder started mid-run) lost nothing before their first received message as far as the recording is
concerned; a writer that appeared later lost its first (first received − 1) messages to the recording
(published before the recorder's subscription matched it).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass


@dataclass
class WriterCount:
    """What one recording received of one writer: its first and newest sequence number, how many messages,
    how many missing between them (`gaps`) and before the first (`before_match`, writers that appeared
    after the recording began)."""

    topic: str
    node: str
    gid: str
    first: int
    last: int
    received: int = 1
    gaps: int = 0
    before_match: int = 0

    @property
    def lost(self) -> int:
        return self.gaps + self.before_match


class SequenceGaps:
    """Per-writer counts of received and lost messages of a recording."""

    def __init__(self):
        self.writers: dict[tuple[str, bytes], WriterCount] = {}
        self._present: set[tuple[str, bytes]] = set()
        #: When the recording began (system clock ns; None: not said), for writers not in the graph then.
        self.began_ns: int | None = None

    def already_publishing(self, topic: str, gids) -> None:
        """Writers of `topic` that published before the recording began: their earlier messages are not lost."""
        self._present.update((topic, bytes(gid)) for gid in gids)

    def add(self, topic: str, gid: bytes, sequence: int, node: str = "", source_ns: int | None = None) -> None:
        """One received message: `sequence` of the writer `gid` (16 bytes) on `topic`, published at `source_ns`
        (system clock ns, when DDS says)."""
        key = (topic, gid)
        writer = self.writers.get(key)
        if writer is None:
            present = key in self._present or self._before_recording(source_ns)
            self.writers[key] = WriterCount(topic, node, gid.hex(), sequence, sequence,
                                            before_match=0 if present else sequence - 1)
            return
        writer.received += 1
        if sequence > writer.last:
            if not self._before_recording(source_ns):  # else the whole gap went before the recording began
                writer.gaps += sequence - writer.last - 1
            writer.last = sequence
        elif sequence < writer.first:  # older than anything received (out of order): it was counted missing
            writer.before_match = max(0, writer.before_match - 1)
            writer.first = sequence
        else:  # late, inside a counted gap
            writer.gaps = max(0, writer.gaps - 1)

    def _before_recording(self, source_ns: int | None) -> bool:
        """Whether a message published at `source_ns` (system clock ns; None: unknown) predates the recording."""
        return source_ns is not None and self.began_ns is not None and source_ns < self.began_ns

    def lost_by_topic(self) -> dict[str, int]:
        lost: dict[str, int] = {}
        for writer in self.writers.values():
            lost[writer.topic] = lost.get(writer.topic, 0) + writer.lost
        return lost

    @property
    def lost(self) -> int:
        return sum(writer.lost for writer in self.writers.values())

    def custom_data(self) -> dict[str, str]:
        """metadata.yaml custom_data entries: `lost_messages` (a number), `lost_messages_by_topic` and
        `writers` (JSON: per writer topic, node, gid, first, last, received, gaps, before_match)."""
        writers = sorted((asdict(w) for w in self.writers.values()), key=lambda w: (w["topic"], w["node"], w["gid"]))
        return {"lost_messages": str(self.lost),
                "lost_messages_by_topic": json.dumps(dict(sorted(self.lost_by_topic().items()))),
                "writers": json.dumps(writers)}
