"""Who else is on a ROS domain: the product's nodes and a haptic device, as the ROS graph shows them.

`liver-sim demo`, `bench loop` and `replay` start nodes or publish the product's topics; on a domain where
a bridge, a physics or a device already runs they would drive the same device (two bridges interleaving
their commands defeat the rate limit) or feed the running nodes. They look first and refuse
(:func:`refuse_occupied`). `ROS_DOMAIN_ID` 0 is shared by every user of a host.
"""
from __future__ import annotations

import os
import time

from liver_sim.base.topic_names import in_namespace, tool_topic

#: The product's node names (each node's loop inputs live in a hidden node `_<name>_loop`).
PRODUCT_NODES = ("liver_physics", "haptic_bridge", "liver_tool", "phantom_sim")
#: The name the graph gives an endpoint whose node it has not learnt yet.
UNKNOWN_NODE_NAME = "_NODE_NAME_UNKNOWN_"
#: How long (s) a new participant lets discovery run before it takes the graph as complete: longer than Fast
#: DDS's participant announcement period (3 s), for when the first announcements are lost on a busy machine.
DISCOVERY_WAIT_S = 3.5
#: How often (s) the graph is looked at meanwhile.
GRAPH_POLL_S = 0.25


class DomainOccupied(RuntimeError):
    """The ROS domain already has the product's nodes or a device: names them."""


def node_path(namespace: str, name: str) -> str:
    """The fully qualified name of a node: /ns/name, /name in the root namespace."""
    return f"{namespace.rstrip('/')}/{name}"


def publisher_nodes(node, topic: str) -> list[str]:
    """The fully qualified names of the nodes publishing on `topic`, one per publisher, as `node`'s graph
    knows them."""
    return [node_path(info.node_namespace, info.node_name) for info in node.get_publishers_info_by_topic(topic)]


def _owner(name: str) -> str:
    """The node a hidden loop-input node `_<name>_loop` belongs to; other names as they are."""
    return name[1:].removesuffix("_loop") if name.startswith("_") else name


def domain_occupants(node, ignore: tuple[str, ...] = ()) -> list[str]:
    """What already runs on `node`'s domain: the product's nodes, and any node publishing a device's measured
    pose (a device driver) or its force command (another bridge), in the root namespace or a node's; `node` itself
    and the nodes named in `ignore` aside (with their hidden loop-input nodes). Subscribers are observers (a viewer,
    a recorder) and welcome. A node killed hard stays in the graph until its DDS lease ends (about 20 s)."""
    ignored = {node.get_name(), *ignore}
    found = []
    nodes = node.get_node_names_and_namespaces()
    for name, namespace in nodes:
        if _owner(name) in PRODUCT_NODES and _owner(name) not in ignored:
            found.append(f"node {node_path(namespace, _owner(name))}")
    namespaces = sorted({"/", *(namespace for _, namespace in nodes)})
    for topic in [in_namespace(tool_topic(key), namespace) for namespace in namespaces
                  for key in ("measured_cp", "servo_cf")]:
        for info in node.get_publishers_info_by_topic(topic):
            if info.node_name == UNKNOWN_NODE_NAME:
                found.append(f"a node (its name not discovered yet) publishing {topic}")
                continue
            owner = _owner(info.node_name)
            if owner not in PRODUCT_NODES and owner not in ignored:
                found.append(f"node {node_path(info.node_namespace, owner)} publishing {topic}")
    return sorted(set(found))


def refuse_occupied(node, what: str, ignore: tuple[str, ...] = (), wait_s: float = DISCOVERY_WAIT_S) -> None:
    """DomainOccupied naming what :func:`domain_occupants` finds on the domain within `wait_s` of discovery
    (looked at every GRAPH_POLL_S; an occupant found ends the wait, and a name still undiscovered gets a little
    longer)."""
    deadline = time.monotonic() + wait_s
    occupants = domain_occupants(node, ignore)
    while time.monotonic() < deadline and not (occupants and not any("not discovered" in o for o in occupants)):
        time.sleep(GRAPH_POLL_S)
        occupants = domain_occupants(node, ignore)
    if occupants:
        raise DomainOccupied(f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')} already has "
                           f"{'; '.join(occupants)}: {what} would share its device and topics; stop them or give "
                           "this run a ROS_DOMAIN_ID of its own")
