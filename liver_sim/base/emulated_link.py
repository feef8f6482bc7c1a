"""An emulated network link (no ROS): delay, jitter and loss between a teleoperator's side and the remote side.

A message that arrived at `arrival_s` is lost with probability `loss_fraction` (a seeded generator, so a run
repeats), or released at

    release_s = max(arrival_s + delay_s + u·jitter_s, the previous message's release_s),   u ~ U(−1, 1),

never before its arrival: as `tc netem delay D J`, but in order. Jitter never reorders: a DDS reader keeps the
order of one writer's samples (it drops a best-effort sample older than one it already has), so a late message
holds back the ones behind it instead of overtaking them. The queue is bounded (`capacity` messages); when full,
the oldest waiting message is dropped and counted (`overflowed`). Times are seconds on one clock (monotonic).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from liver_sim.base.parameters import Param

#: Messages one link holds at most: 2 s of a 1 kHz stream at the largest delay.
LINK_CAPACITY = 2048

#: The link parameters of a node that takes its inputs over the emulated link (liver_physics: the tool pose;
#: haptic_bridge: the local model or the physics wrench). All zero: no link, the inputs are taken as they arrive.
LINK_PARAMETERS = {
    "link_delay_s": Param(0.0, "emulated one-way delay (s) on the inputs from the other side of the teleoperation "
                          "link (a round trip is twice it); 0 with no jitter and no loss: no emulation", 0.0, 1.0),
    "link_jitter_s": Param(0.0, "emulated jitter (s): each message's delay is link_delay_s ± up to this "
                           "(uniform, never below 0); messages stay in order", 0.0, 1.0),
    "link_loss_fraction": Param(0.0, "fraction of messages the emulated link loses (0-1)", 0.0, 1.0),
    "link_seed": Param(0, "seed of the emulated link's jitter and loss (a run repeats)", 0, 2**31 - 1),
}


@dataclass(frozen=True)
class LinkSettings:
    """One-way delay (s), jitter (s), loss fraction (0-1) and seed of an emulated link."""

    delay_s: float = 0.0
    jitter_s: float = 0.0
    loss_fraction: float = 0.0
    seed: int = 0

    @classmethod
    def from_parameters(cls, p) -> LinkSettings:
        """The settings of a node's LINK_PARAMETERS in its typed parameter record `p`."""
        return cls(p.link_delay_s, p.link_jitter_s, p.link_loss_fraction, p.link_seed)

    def parameters(self) -> dict:
        """These settings as the LINK_PARAMETERS of a node."""
        return {"link_delay_s": float(self.delay_s), "link_jitter_s": float(self.jitter_s),
                "link_loss_fraction": float(self.loss_fraction), "link_seed": int(self.seed)}

    @property
    def emulated(self) -> bool:
        """Whether the link does anything: at zero delay, jitter and loss the inputs bypass it."""
        return self.delay_s > 0.0 or self.jitter_s > 0.0 or self.loss_fraction > 0.0


class EmulatedLink:
    """The bounded, in-order queue of one input over an emulated link (module docstring)."""

    def __init__(self, settings: LinkSettings, capacity: int = LINK_CAPACITY):
        self.settings = settings
        self._random = np.random.default_rng(settings.seed)
        self._queue: deque = deque()
        self._capacity = capacity
        self._last_release_s = -np.inf
        self.sent = self.lost = self.overflowed = 0

    def send(self, item, arrival_s: float) -> None:
        """`item` arrived at `arrival_s` (s): lost, or queued for its release time."""
        s = self.settings
        self.sent += 1
        if s.loss_fraction > 0.0 and self._random.random() < s.loss_fraction:
            self.lost += 1
            return
        delay = s.delay_s + (s.jitter_s * self._random.uniform(-1.0, 1.0) if s.jitter_s > 0.0 else 0.0)
        release = max(arrival_s + max(delay, 0.0), self._last_release_s)
        self._last_release_s = release
        if len(self._queue) == self._capacity:
            self._queue.popleft()
            self.overflowed += 1
        self._queue.append((release, item))

    def receive(self, now_s: float) -> list:
        """Every (item, release time s) released by `now_s`, oldest first; they leave the queue."""
        released = []
        queue = self._queue
        while queue and queue[0][0] <= now_s:
            release, item = queue.popleft()
            released.append((item, release))
        return released

    @property
    def waiting(self) -> int:
        """Messages in the queue, not yet released."""
        return len(self._queue)

    def counts(self) -> dict:
        """For diagnostics: messages sent into the link, lost, dropped by a full queue, and waiting."""
        return {"link_sent": self.sent, "link_lost": self.lost, "link_overflowed": self.overflowed,
                "link_waiting": self.waiting}


def link_text(link: EmulatedLink | None) -> str:
    """How a node's start-up line names its emulated link: '' without one."""
    if link is None:
        return ""
    s = link.settings
    return (f" over an emulated link (delay {s.delay_s * 1e3:g} ms, jitter ±{s.jitter_s * 1e3:g} ms, "
            f"loss {s.loss_fraction:g}, seed {s.seed})")
