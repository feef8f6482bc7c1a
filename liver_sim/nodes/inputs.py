"""What a node's loop reads: subscriptions it takes itself (LoopInputs), the newest value of each input and
when it arrived (Latest)."""
from __future__ import annotations

import time

import numpy as np
import rclpy


class Latest:
    """The newest value of something and when it arrived (monotonic seconds).

    One tuple swapped whole (atomic under the GIL): no lock, and a reader never sees a value with
    another's arrival time."""

    def __init__(self):
        self._item = (None, -np.inf)

    def set(self, value, received: float | None = None) -> None:
        """Keep `value`, received at monotonic `received` (s; default: now)."""
        self._item = (value, time.monotonic() if received is None else received)

    def get(self):
        """(value, monotonic arrival time); (None, -inf) before the first value."""
        return self._item


class LoopInputs:
    """Subscriptions that a rate loop reads itself, bypassing the executor's per-message cost.

    They belong to a hidden node (`_<node>_loop`, not spun by any executor); `poll()`, called from
    the loop, takes every waiting message of each subscription and hands the newest to its callback
    (with `received=True`, as callback(message, monotonic s at which DDS received it), so that ages count
    from reception, not from the poll), or, for a subscription made with `every=True`, each message with its
    rmw info (a dict with `source_timestamp` and `received_timestamp`, system-clock ns, and
    `publication_sequence_number`).
    """

    def __init__(self, node):
        self._owner = node
        self._node = rclpy.create_node(f"_{node.get_name()}_loop", context=node.context,
                                       use_global_arguments=False, start_parameter_services=False,
                                       enable_rosout=False)
        self._inputs = []

    def subscribe(self, msg_type, topic: str, qos, callback, raw: bool = False, every: bool = False,
                  received: bool = False):
        """Subscribe to `topic` as the owning node names it (its namespace and remappings, `-r from:=to`,
        applied); returns the subscription (its get_publisher_count() tells whether anyone publishes)."""
        resolved = self._owner.resolve_topic_name(topic)
        subscription = self._node.create_subscription(msg_type, resolved, callback, qos, raw=raw)
        self._inputs.append((subscription, callback, every, received))
        return subscription

    def poll(self) -> None:
        for subscription, callback, every, received in self._inputs:
            newest = None
            with subscription.handle:
                while (taken := subscription.handle.take_message(subscription.msg_type, subscription.raw)):
                    if every:
                        callback(*taken)
                    else:
                        newest = taken
            if newest is None:
                continue
            if received:
                callback(newest[0], received_monotonic(newest[1]))
            else:
                callback(newest[0])

    def destroy(self) -> None:
        self._node.destroy_node()


def received_monotonic(info: dict) -> float:
    """Monotonic time (s) at which DDS received a message, from its rmw info's `received_timestamp`
    (system clock ns); now when the middleware gives none."""
    stamp = info.get("received_timestamp", 0) if info else 0
    now = time.monotonic_ns()
    if not stamp:
        return now * 1e-9
    return min(stamp + (now - time.time_ns()), now) * 1e-9
