"""What the bridge's loop renders from, judged (no ROS): the newest device sample and source input (the local model,
or the physics wrench with `local_model: none`), each refused and counted with its reason when it cannot be used,
the device map offered by the executor (its K·scale checked), and the parameters offered at run time.

A device sample counts only once it is usable: decoded, finite, stamped no more than `stamp_lead_tolerance_s` ahead
of the clock, and placing the tool inside the workspace. Its age is the age of the newest usable sample, so a device
reporting nonsense is a device reporting nothing: the watchdog ramps the force to zero and a soft start follows once
usable samples return. The node side (liver_sim.nodes.bridge_shell) hands samples in only from the input's source
writer (haptic_bridge.sources).
"""
from __future__ import annotations

import math

from haptic_bridge.inputs import InputCheck
from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.tick import BridgeTick, check_passivity
from liver_sim.base.geometry.device_map import DeviceMap

#: The inputs whose bad samples are counted: the loop's three and the device map.
KINDS = ("device_pose", "local_model", "tool_wrench", "device_map")


class Handoff:
    """A value one thread hands to another to take once: :meth:`offer` replaces a value not yet taken, :meth:`take`
    returns it once, then `Handoff.NOTHING` until the next offer. One tuple swapped whole (atomic under the GIL):
    one offering thread, one taking thread, no lock."""

    NOTHING = object()

    def __init__(self):
        self._offered = (0, Handoff.NOTHING)
        self._taken = 0

    def offer(self, value) -> None:
        self._offered = (self._offered[0] + 1, value)

    def take(self):
        """The value offered since the last take, or NOTHING."""
        version, value = self._offered
        if version == self._taken:
            return Handoff.NOTHING
        self._taken = version
        return value

    @property
    def pending(self) -> bool:
        """Whether an offer waits to be taken."""
        return self._offered[0] != self._taken


class Intake:
    """The loop's inputs for the parameters `p`: `decoders` maps each input kind to a function of its serialized
    bytes returning a tuple (its value first: a position (m, device frame) and (sec, nanosec) stamp; a local model;
    a force), raising ValueError for bad bytes."""

    def __init__(self, p: BridgeParameters, decoders: dict):
        self.p = p
        self.source_kind = "tool_wrench" if p.local_model == "none" else "local_model"
        self._decoders = decoders
        checks = InputCheck(p.workspace_centre_m, p.workspace_radius_m)
        self._checks = {"device_pose": lambda _: None, "local_model": checks.model, "tool_wrench": checks.force}
        self._tip_check = checks.tip
        self.bad = dict.fromkeys(KINDS, 0)
        self.reasons: dict[str, str] = {}
        self._pose = (None, -math.inf)    # the newest decoded device sample, its reception (monotonic s)
        self._sampled = None              # the device sample last judged
        self._tip = (None, -math.inf)     # the newest usable tool tip (m, liver frame), its sample's reception
        self._source = (None, -math.inf)  # the newest plausible source input, its reception
        self.params, self.maps = Handoff(), Handoff()  # for the loop's next tick
        self.newest_map: DeviceMap | None = None       # the newest map handed to the loop
        self.map_problem: str | None = "waiting for the device map"
        self.last_force_n = 0.0

    # -- in the loop's poll
    def offer(self, kind: str, data: bytes, received_s: float) -> None:
        """A sample of input `kind` from its source, received at monotonic `received_s`."""
        try:
            value = self._decoders[kind](data)
            problem = self._checks[kind](value[0])
        except ValueError as exc:
            problem = str(exc)
        if problem:
            self.refuse(kind, problem)
        elif kind == "device_pose":
            self._pose = (value, received_s)
        else:
            self._source = (value, received_s)

    def refuse(self, kind: str, reason: str) -> None:
        """Count a refused sample of `kind`; the reason is logged by the diagnostics, not in the loop."""
        self.bad[kind] += 1
        self.reasons[kind] = reason

    # -- in the loop's tick
    def tick_inputs(self, tick: BridgeTick, now_s: float, clock_s: float):
        """(tip, pose age s, source, source age s, stamp) for `tick.step` at monotonic `now_s`, `clock_s` being the
        device stamps' clock (s) now; the stamp is the newest device sample's (the wrench's with local_model none). A
        new device sample is judged here: its tip placed through the tick's device map, then refused when stamped in the
        future or outside the workspace."""
        pose, received = self._pose
        if pose is not None and pose is not self._sampled:
            self._sampled = pose
            self._judge_sample(tick, pose, received, now_s, clock_s)
        tip, tip_received = self._tip
        source, source_received = self._source
        stamp = pose[1] if pose is not None else None
        if self.source_kind == "local_model" and source is not None:
            lifetime = self.p.lifetime_s
            source = (source[0], min(source[1], lifetime) if source[1] > 0.0 else lifetime)
        elif self.source_kind == "tool_wrench":  # the held wrench: the command carries its stamp
            source, stamp = (source[0], source[1]) if source is not None else (None, None)
        return (tip if tick.device_map is not None else None, now_s - tip_received, source,
                now_s - source_received, stamp)

    def _judge_sample(self, tick: BridgeTick, pose, received_s: float, now_s: float, clock_s: float) -> None:
        (sec, nanosec), position = pose[1], pose[0]
        stamp_s = sec + nanosec * 1e-9
        lead_s = stamp_s - clock_s
        if lead_s > self.p.stamp_lead_tolerance_s:
            self.refuse("device_pose", f"stamped {lead_s:.3g} s ahead of the clock, beyond "
                                       f"stamp_lead_tolerance_s={self.p.stamp_lead_tolerance_s:g}")
            return
        tip = tick.sample(stamp_s, clock_s - (now_s - received_s), position)
        if tip is None:
            return
        problem = self._tip_check(tip)
        if problem:
            self.refuse("device_pose", problem)
        else:
            self._tip = (tip, received_s)

    def ages(self, now_s: float) -> dict:
        """Seconds since the newest usable device sample and source input arrived."""
        return {"device_pose": now_s - self._tip[1], "source": now_s - self._source[1]}

    # -- the device map and the parameters (executor thread)
    def offer_map(self, device_map: DeviceMap, source: str) -> str | None:
        """A map from the source: handed to the loop, or refused when K·scale is not passive with the parameters
        (`drives_device`); the reason, or None."""
        if self.p.drives_device:
            try:
                check_passivity(self.p, device_map.scale)
            except ValueError as exc:
                self.withdraw_map(f"device map refused: from {source}: {exc}")
                return self.map_problem
        self.map_problem = None
        self.newest_map = device_map
        self.maps.offer(device_map)
        return None

    def withdraw_map(self, problem: str) -> None:
        """No usable map (refused from its source, or the source ambiguous): zero force until a good one."""
        self.map_problem = problem
        self.newest_map = None
        self.maps.offer(None)

    def scales(self, tick: BridgeTick) -> tuple[float, ...]:
        """Every device scale the loop may render with: the map in use, one waiting, the newest offered."""
        maps = (tick.device_map, tick.map_waiting, self.newest_map)
        return tuple({m.scale for m in maps if m is not None}) or (1.0,)

    def offer_params(self, p: BridgeParameters) -> None:
        self.p = p
        self.params.offer(p)
