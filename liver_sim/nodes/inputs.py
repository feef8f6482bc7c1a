"""What a node's loop reads: subscriptions it takes itself (LoopInputs), the newest value of each input and
when it arrived (Latest)."""
from __future__ import annotations

import time

import numpy as np
import rclpy

from haptic_bridge.sources import ACCEPT, WriterGate
from liver_sim.base.emulated_link import EmulatedLink, LinkSettings
from liver_sim.nodes.rcl_take import SerializedTake
from msg_defs.stamps import stamp_s_from_bytes


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


class RosTime:
    """Stamps on a node's ROS clock at the cost of the system clock's: time.time_ns unless the node runs on /clock
    (use_sim_time), then its clock. Which one is read at construction and at each :meth:`refresh` (a node calls it
    from its 1 s timer), not at every stamp (asking costs as much as the system clock's time itself)."""

    def __init__(self, node):
        self._clock = node.get_clock()
        self.refresh()

    def refresh(self) -> None:
        self._simulated = self._clock.ros_time_is_active

    def stamp(self) -> tuple[int, int]:
        """(sec, nanosec) now."""
        return divmod(self._clock.now().nanoseconds if self._simulated else time.time_ns(), 1_000_000_000)


class LoopInputs:
    """Subscriptions that a rate loop reads itself, bypassing the executor's per-message cost.

    They belong to a hidden node (`_<node>_loop` in the node's namespace, not spun by any executor); `poll()`, called
    from
    the loop, takes every waiting message of each subscription and hands the newest to its callback
    (with `received=True`, as callback(message, monotonic s at which DDS received it), so that ages count
    from reception, not from the poll), or, for a subscription made with `every=True`, each message with its
    rmw info (a dict with `source_timestamp` and `received_timestamp`, system-clock ns, and
    `publication_sequence_number`).

    A subscription given a WriterGate (haptic_bridge.sources) takes every waiting message with its writer's GID and
    hands on only the newest of the writer the gate accepts (the others are counted by the gate), as
    callback(Taken, monotonic s of reception) (liver_sim.nodes.rcl_take.Taken: a message over `max_bytes` comes with
    empty data and its size, never copied into Python).

    A subscription given an EmulatedLink (liver_sim.base.emulated_link) sends every message into it, timed by its
    reception, and hands the callback the newest one the link has released by the poll, with its release time
    as its reception (`received=True`): an input's age counts from its emulated arrival. The owner node's clock
    minus the header stamp of each released message is the delay a rig sees on the wire (`link_delay_s`).
    """

    def __init__(self, node):
        self._owner = node
        self._node = rclpy.create_node(f"_{node.get_name()}_loop", namespace=node.get_namespace(),
                                       context=node.context, use_global_arguments=False,
                                       start_parameter_services=False, enable_rosout=False)
        self._inputs = []
        #: topic -> the newest (owner's ROS time − header stamp) (s) of a message its link released
        self.link_delay_s: dict[str, float] = {}

    def subscribe(self, msg_type, topic: str, qos, callback, raw: bool = False, every: bool = False,
                  received: bool = False, link: EmulatedLink | None = None, gate: WriterGate | None = None,
                  max_bytes: int | None = None):
        """Subscribe to `topic` as the owning node names it (its namespace and remappings, `-r from:=to`,
        applied); returns the subscription (its get_publisher_count() tells whether anyone publishes).
        With `link`, raw messages of a stamped type pass through it; with `gate`, only its writer's (class
        docstring)."""
        resolved = self._owner.resolve_topic_name(topic)
        subscription = self._node.create_subscription(msg_type, resolved, callback, qos, raw=raw or gate is not None)
        if gate is not None:
            self._inputs.append((subscription, callback, SerializedTake(subscription, max_bytes=max_bytes), gate,
                                 link))
            return subscription
        once = qos.depth == 1 and not every and link is None  # the reader keeps the newest message only: one take
        self._inputs.append((subscription, callback, every, received, link, once))
        return subscription

    def poll(self) -> None:
        for entry in self._inputs:
            if isinstance(entry[3], WriterGate):
                self._poll_gated(*entry)
            else:
                self._poll(*entry)

    def _poll_gated(self, subscription, callback, take: SerializedTake, gate: WriterGate,
                    link: EmulatedLink | None) -> None:
        newest = None
        while (taken := take()) is not None:
            if gate.judge(taken.gid) != ACCEPT:
                continue
            if link is not None:
                link.send(taken, monotonic_of(taken.received_ns))
            else:
                newest = taken
        if link is not None:
            self._release(subscription, callback, True, link)
        elif newest is not None:
            callback(newest, monotonic_of(newest.received_ns))

    def _poll(self, subscription, callback, every: bool, received: bool, link: EmulatedLink | None,
              once: bool) -> None:
        newest = None
        with subscription.handle:
            if once:
                newest = subscription.handle.take_message(subscription.msg_type, subscription.raw)
            else:
                while (taken := subscription.handle.take_message(subscription.msg_type, subscription.raw)):
                    if link is not None:
                        link.send(taken[0], received_monotonic(taken[1]))
                    elif every:
                        callback(*taken)
                    else:
                        newest = taken
        if link is not None:
            self._release(subscription, callback, received, link)
            return
        if newest is None:
            return
        if received:
            callback(newest[0], received_monotonic(newest[1]))
        else:
            callback(newest[0])

    def _release(self, subscription, callback, received: bool, link: EmulatedLink) -> None:
        """Hand `callback` the newest message `link` has released by now, timed by its release."""
        released = link.receive(time.monotonic())
        if not released:
            return
        data, release_s = released[-1]
        try:
            stamp_s = stamp_s_from_bytes(getattr(data, "data", data), subscription.msg_type.__name__)
        except ValueError:
            pass  # the callback refuses it with the reason
        else:
            self.link_delay_s[subscription.topic_name] = self._owner.get_clock().now().nanoseconds * 1e-9 - stamp_s
        if received:
            callback(data, release_s)
        else:
            callback(data)

    def destroy(self) -> None:
        for entry in self._inputs:
            if isinstance(entry[2], SerializedTake):
                entry[2].close()
        self._node.destroy_node()


def emulated_link(p) -> EmulatedLink | None:
    """The EmulatedLink of the link parameters (liver_sim.base.emulated_link.LINK_PARAMETERS) in a node's record `p`, or
    None when they emulate nothing: the inputs then bypass it at no cost."""
    settings = LinkSettings.from_parameters(p)
    return EmulatedLink(settings) if settings.emulated else None


def link_report(link: EmulatedLink | None, inputs: LoopInputs) -> dict:
    """Diagnostics of a node's emulated link: its settings, counts (EmulatedLink.counts) and the delay measured
    by header stamps of what it released last (`link_delay_measured_s`); {} without a link."""
    if link is None:
        return {}
    s = link.settings
    measured = max(inputs.link_delay_s.values(), default=float("nan"))
    return {"link_delay_s": s.delay_s, "link_jitter_s": s.jitter_s, "link_loss_fraction": s.loss_fraction,
            **link.counts(), "link_delay_measured_s": measured}


def received_monotonic(info: dict) -> float:
    """Monotonic time (s) at which DDS received a message, from its rmw info's `received_timestamp`
    (system clock ns); now when the middleware gives none."""
    return monotonic_of(info.get("received_timestamp", 0) if info else 0)


def monotonic_of(stamp: int) -> float:
    """Monotonic time (s) of a reception `stamp` (system clock ns, 0: none given: now)."""
    now = time.monotonic_ns()
    if not stamp:
        return now * 1e-9
    return min(stamp + (now - time.time_ns()), now) * 1e-9
