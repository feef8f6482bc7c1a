"""Which device map a bridge may take: each map sample is judged by the writer that sent it.

A bridge takes the device map only from one node, `source_node` (its parameter `device_map_node`, default
`liver_tool`: a relative name is the node of that name in the bridge's own namespace). A DDS message carries no
sender name, but each sample carries its writer's GID (liver_sim.nodes.rcl_take), and the ROS graph names the node
behind every writer GID. So a map is bound to the node that wrote it, not to a snapshot of who publishes on the
topic when it is looked at:

- from `source_node`: decoded and handed on (`on_map`); one that does not decode is refused from the source
  (`on_refused(reason, True)`: the bridge then renders zero until the source sends a good one);
- from any other node, good or bad: refused (`on_refused(reason, False)`), and nothing else changes;
- from a writer the graph does not name (yet): kept, and judged at each poll once the graph names it; a writer
  still unnamed after `writer_wait_s` — one that published and left before discovery named it — is refused.

The subscription is reliable and transient local (the map is latched) and belongs to a hidden node no executor
spins: :meth:`DeviceMapSource.poll`, from a timer of the owner's executor every `poll_s`, takes the samples.
"""
from __future__ import annotations

import time

import rclpy
from rclpy.serialization import deserialize_message

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.nodes.occupants import UNKNOWN_NODE_NAME, node_path
from liver_sim.nodes.rcl_take import SerializedTake, Taken, endpoint_gid
from msg_defs.device_map import device_map_from_message
from msg_defs.topics import TOPICS

#: How often (s) the map subscription is read and its undecided samples judged again.
MAP_POLL_S = 0.1
#: How long (s) a sample waits for the graph to name its writer: longer than a participant announcement period
#: (3 s) with a lost first announcement on a busy machine.
MAP_WRITER_WAIT_S = 5.0
#: Most undecided samples kept; beyond, the oldest is refused (a flood of maps from unnamed writers).
MAX_UNDECIDED = 64


def decode_device_map(data: bytes) -> DeviceMap:
    """The DeviceMap of a serialized /tool/device_map message, or ValueError naming what is wrong."""
    try:
        message = deserialize_message(data, TOPICS["device_map"].type)
    except Exception as exc:  # noqa: BLE001 — whatever the deserializer raises on foreign bytes
        raise ValueError(f"the message does not decode as {TOPICS['device_map'].type.__name__}: {exc}") from None
    return device_map_from_message(message)


class DeviceMapSource:
    """The device map samples on `topic` (as `owner` resolves it), judged by their writer (module docstring).

    `on_map(device_map)`: a map from `source_node`; `on_refused(reason, from_source)`: a refused sample.
    Counts: `taken`, `refused`."""

    def __init__(self, owner, topic: str, source_node: str, on_map, on_refused, poll_s: float = MAP_POLL_S,
                 writer_wait_s: float = MAP_WRITER_WAIT_S):
        self._owner = owner
        self.topic = owner.resolve_topic_name(topic)
        self.source_node = source_node if source_node.startswith("/") else node_path(owner.get_namespace(),
                                                                                      source_node)
        self._on_map, self._on_refused = on_map, on_refused
        self.writer_wait_s = writer_wait_s
        self._node = rclpy.create_node(f"_{owner.get_name()}_device_map", namespace=owner.get_namespace(),
                                       context=owner.context, use_global_arguments=False,
                                       start_parameter_services=False, enable_rosout=False)
        subscription = self._node.create_subscription(TOPICS["device_map"].type, self.topic, lambda _: None,
                                                      TOPICS["device_map"].qos, raw=True)
        self._take = SerializedTake(subscription)
        self._undecided: list[tuple[Taken, float]] = []  # (sample, monotonic deadline), in arrival order
        self.taken = self.refused = 0
        self._timer = owner.create_timer(poll_s, self.poll)

    def poll(self) -> None:
        """Take the waiting samples and judge, in arrival order, every one whose writer the graph names."""
        now = time.monotonic()
        while (sample := self._take()) is not None:
            self._undecided.append((sample, now + self.writer_wait_s))
        while len(self._undecided) > MAX_UNDECIDED:
            self._refuse(f"more than {MAX_UNDECIDED} maps wait for their writer to be named", False)
            del self._undecided[0]
        if not self._undecided:
            return
        writers = {endpoint_gid(info): node_path(info.node_namespace, info.node_name)
                   for info in self._node.get_publishers_info_by_topic(self.topic)
                   if info.node_name != UNKNOWN_NODE_NAME}
        undecided = []
        for sample, deadline in self._undecided:
            writer = writers.get(sample.gid)
            if writer is None and now < deadline:
                undecided.append((sample, deadline))
            elif writer is None:
                self._refuse(f"its writer was not named by the ROS graph within {self.writer_wait_s:g} s (it "
                             "published and left before discovery named it)", False)
            elif writer != self.source_node:
                self._refuse(f"sent by {writer}; only {self.source_node} may send it (parameter device_map_node)",
                             False)
            else:
                self._judge(sample.data, writer)
        self._undecided = undecided

    @property
    def waiting(self) -> int:
        """Samples whose writer the graph has not named yet."""
        return len(self._undecided)

    def _judge(self, data: bytes, writer: str) -> None:
        try:
            device_map = decode_device_map(data)
        except ValueError as exc:
            self._refuse(f"sent by {writer}: {exc}", True)
            return
        self.taken += 1
        self._on_map(device_map)

    def _refuse(self, reason: str, from_source: bool) -> None:
        self.refused += 1
        self._on_refused(reason, from_source)

    def destroy(self) -> None:
        self._owner.destroy_timer(self._timer)
        self._take.close()
        self._node.destroy_node()
