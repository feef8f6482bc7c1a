"""The ROS graph as a haptic_bridge.sources.WriterGate needs it: who writes on a topic (writer GID → node) and which
nodes there are, looked at from a node's executor thread (never from a 1 kHz loop: a graph query costs
milliseconds)."""
from __future__ import annotations

from haptic_bridge.sources import WriterGate
from liver_sim.nodes.occupants import UNKNOWN_NODE_NAME, node_path
from liver_sim.nodes.rcl_take import endpoint_gid


def source_node(owner, name: str) -> str:
    """The fully qualified name of the source node `name` as `owner` reads it: an absolute name as it is, a relative
    one in `owner`'s namespace (/left/liver_tool for `liver_tool` read by a node in /left)."""
    return name if name.startswith("/") else node_path(owner.get_namespace(), name)


def topic_writers(node, topic: str) -> dict[bytes, str]:
    """GID → fully qualified node of every writer on `topic` whose node the graph names."""
    return {endpoint_gid(info): node_path(info.node_namespace, info.node_name)
            for info in node.get_publishers_info_by_topic(topic) if info.node_name != UNKNOWN_NODE_NAME}


def graph_nodes(node) -> list[str]:
    """The fully qualified name of every node of the graph, a name twice when two nodes share it."""
    return [node_path(namespace, name) for name, namespace in node.get_node_names_and_namespaces()]


def update_gates(node, gates: dict[str, WriterGate]) -> None:
    """Hand each gate (by its resolved topic) what `node`'s graph shows now."""
    nodes = graph_nodes(node)
    for topic, gate in gates.items():
        gate.update(topic_writers(node, topic), nodes)
