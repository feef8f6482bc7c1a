"""Which writer an input is taken from (no ROS): each input of the force loop has one source node, named by a
parameter and fixed at start, and each sample is judged by the GID of the writer that sent it.

A DDS sample carries its writer's GID; the ROS graph names the node behind every writer GID (the node side,
liver_sim.nodes.source_graph, hands :meth:`WriterGate.update` what the graph shows). So a sample is bound to the node
that wrote it, not to a snapshot of who publishes on the topic:

- the first writer of the source node the graph shows is accepted and pinned: its GID stays the one accepted until
  it leaves the graph (a node started later under the same name cannot take its place);
- two nodes in the graph with the source's name, or two writers on the topic named as the source, make the input
  ambiguous: nothing is accepted until one has gone ("two nodes named X");
- a sample of any other writer is refused and counted, and the writers refused are named;
- a sample whose writer the graph does not name yet is `UNKNOWN` (a reader that can wait may keep it; the 1 kHz loop
  drops it).

:meth:`judge` runs in the reading thread (a loop at 1 kHz): one tuple read, a comparison, no allocation.
:meth:`update` runs wherever the graph is looked at; the accepted GID is swapped whole (atomic under the GIL).
"""
from __future__ import annotations

ACCEPT, REFUSE, UNKNOWN = "accept", "refuse", "unknown"
#: Most refused writers remembered by GID for diagnostics (a flood of new writers grows nothing beyond it).
MAX_REFUSED_WRITERS = 16
#: The name diagnostics give a refused writer the graph has not named (it published and left before discovery).
UNNAMED_WRITER = "a writer the graph has not named"


class WriterGate:
    """The writers of one input topic judged against its source node `source` (fully qualified, /ns/name);
    `parameter` is the parameter that names it (for the reasons given)."""

    def __init__(self, source: str, parameter: str):
        self.source = source
        self.parameter = parameter
        self._accepted = None       # the GID taken from, or None: swapped whole
        self._pinned = None         # the source's writer first accepted, until it leaves the graph
        self._named: dict[bytes, str] = {}
        self.ambiguous = False
        self.refused = 0
        self._refused_writers: dict[bytes, int] = {}  # GID → samples refused

    def update(self, writers: dict[bytes, str], nodes: list[str]) -> None:
        """The graph now: `writers`, GID → node (fully qualified) of every named writer on the topic; `nodes`, the
        fully qualified name of every node in the graph (a name twice when two nodes share it)."""
        if self._pinned is not None and self._pinned not in writers:
            self._pinned = None  # the source's node has left: the next writer of that name is taken
        from_source = [gid for gid, node in writers.items() if node == self.source]
        self.ambiguous = nodes.count(self.source) > 1 or len(from_source) > 1
        if self._pinned is None and len(from_source) == 1 and not self.ambiguous:
            self._pinned = from_source[0]
        self._named = writers
        self._accepted = None if self.ambiguous else self._pinned

    def judge(self, gid: bytes) -> str:
        """ACCEPT a sample of the accepted writer; REFUSE (counted) one of a writer the graph names, or any while
        the source is ambiguous; UNKNOWN one of a writer not named yet (not counted: :meth:`refuse` it to count)."""
        if gid == self._accepted:
            return ACCEPT
        if gid in self._named or self.ambiguous:
            self.refuse(gid)
            return REFUSE
        return UNKNOWN

    def refuse(self, gid: bytes) -> None:
        """Count a refused sample of writer `gid`."""
        self.refused += 1
        if gid in self._refused_writers or len(self._refused_writers) < MAX_REFUSED_WRITERS:
            self._refused_writers[gid] = self._refused_writers.get(gid, 0) + 1

    @property
    def accepted(self) -> bytes | None:
        return self._accepted

    def from_source(self, gid: bytes) -> bool:
        """Whether the graph names `gid`'s node as the source (the accepted writer or a namesake)."""
        return self._named.get(gid) == self.source

    def writer_name(self, gid: bytes) -> str:
        """The node the graph names behind writer `gid`, or UNNAMED_WRITER."""
        return self._named.get(gid, UNNAMED_WRITER)

    def rivals(self) -> list[str]:
        """The writers whose samples were refused, by name: the node the graph gave them, with the count."""
        return sorted(f"{self.writer_name(gid)} ({count})" for gid, count in list(self._refused_writers.items()))

    def problem(self) -> str | None:
        """Why nothing is taken from the source, or None while its writer is accepted."""
        if self.ambiguous:
            return f"two nodes named {self.source} (parameter {self.parameter}): input refused until one leaves"
        if self._accepted is None:
            return f"no writer of {self.source} (parameter {self.parameter}) in the graph yet"
        return None
