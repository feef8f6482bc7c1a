"""The bridge's force topic: its one writer (commands and the supervisor's zeros alike: DDS keeps order within a
writer only, so the last sample a driver receives after any stop is zero) and the watch for any other writer there.

Two bridges interleaving their commands on one device would defeat the rate limit and the watchdog. Another writer
is seen two ways, both from the executor (:meth:`ForceOutput.check`, every GRAPH_CHECK_S): in the graph, which names
every publisher on the topic while it stays (the bridge then sends zero until it has gone), and by the writer GID of
every sample on the topic, read back by a reader of the bridge's own, so that a writer that sends a burst and leaves
between two looks at the graph is still seen and reported.
"""
from __future__ import annotations

import rclpy

from liver_sim.nodes.occupants import UNKNOWN_NODE_NAME, node_path
from liver_sim.nodes.rcl_take import SerializedTake, endpoint_gid, publisher_gid
from msg_defs.forces import force_message_type
from msg_defs.topics import TOPICS, loop_input_qos

#: Samples the read-back keeps between two checks: GRAPH_CHECK_S of the bridge's own commands at up to 5 kHz and a
#: burst beside them.
READ_BACK_DEPTH = 2000
#: The name of a writer gone before the graph named it.
GONE_WRITER = "a writer gone before the graph named it"


class ForceOutput:
    """The writer on `p.force_topic` and what else writes there: `rivals` (the other publishers the graph shows now,
    by node) and `bursts` (samples of other writers read back since the last :meth:`take_bursts`, by writer).
    On a lifecycle node the writer is a lifecycle publisher: it sends only while the node is active."""

    def __init__(self, node, p):
        force_type = force_message_type(p.force_output)
        create = getattr(node, "create_lifecycle_publisher", node.create_publisher)
        self.publisher = create(force_type, p.force_topic, TOPICS["servo_cf"].qos)
        self.topic = self.publisher.topic_name
        self._gid = publisher_gid(self.publisher)
        self._node = rclpy.create_node(f"_{node.get_name()}_force_watch", namespace=node.get_namespace(),
                                       context=node.context, use_global_arguments=False,
                                       start_parameter_services=False, enable_rosout=False)
        read_back = self._node.create_subscription(force_type, self.topic, lambda _: None,
                                                   loop_input_qos(TOPICS["servo_cf"], READ_BACK_DEPTH), raw=True)
        self._take = SerializedTake(read_back, max_bytes=0)  # the GIDs are what counts, not the bytes
        self.rivals: list[str] = []
        self.bursts: dict[str, int] = {}

    def publish(self, message) -> None:
        self.publisher.publish(message)

    def check(self) -> tuple[list[str], list[str]]:
        """Look at the graph and read the samples back, at most READ_BACK_DEPTH of them: (writers that appeared,
        writers gone) since the last check, by name."""
        writers = {endpoint_gid(info): (node_path(info.node_namespace, info.node_name)
                                        if info.node_name != UNKNOWN_NODE_NAME else "a node not yet named by the graph")
                   for info in self._node.get_publishers_info_by_topic(self.topic)}
        writers.pop(self._gid, None)
        for _ in range(READ_BACK_DEPTH):  # at most what the reader keeps: samples arriving meanwhile wait for the next
            if (taken := self._take()) is None:
                break
            if taken.gid != self._gid:
                name = writers.get(taken.gid, GONE_WRITER)
                self.bursts[name] = self.bursts.get(name, 0) + 1
        names = sorted(writers.values())
        appeared, gone = sorted(set(names) - set(self.rivals)), sorted(set(self.rivals) - set(names))
        self.rivals = names
        return appeared, gone

    def take_bursts(self) -> dict[str, int]:
        """Samples of other writers read back since the last call, by writer."""
        bursts, self.bursts = self.bursts, {}
        return bursts

    def destroy(self, node) -> None:
        self._take.close()
        self._node.destroy_node()
        getattr(node, "destroy_lifecycle_publisher", node.destroy_publisher)(self.publisher)
