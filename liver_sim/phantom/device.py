"""The simulated PHANToM without ROS (paper P12, docs/paper.md); liver_sim.phantom.parameters holds the
parameters of the `phantom_sim` node that runs it.

`PhantomSim` stands in for the device: a point mass at the stylus tip held by a virtual hand — a
spring-damper pulling it towards a hand target that plays a `tool_scripts` script — and pushed
by the commanded force, clamped as the real device does. Metres, kilograms, seconds, newtons.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from haptic_bridge.safety import PHANTOM_MAX_FORCE_N
from liver_sim.base.checks import non_negative, positive
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.tool.scripts import ScriptedTrajectory

#: Most integration steps one `advance_to` call takes to catch up; beyond, the script skips ahead.
MAX_CATCH_UP_STEPS = 100


@dataclass(frozen=True)
class StylusParams:
    """The stylus and the hand holding it.

    `mass_kg`: effective mass at the tip; `hand_stiffness_n_per_m`, `hand_damping_ns_per_m`: the
    grip (the defaults make it critically damped, c = 2·√(k·m)); `max_force_n`: the device's force
    clamp (≤ 3.3 N); `workspace_half_m`: the stylus stays in the box ±this (device frame, m).
    """

    mass_kg: float = 0.045
    hand_stiffness_n_per_m: float = 200.0
    hand_damping_ns_per_m: float = 6.0
    max_force_n: float = PHANTOM_MAX_FORCE_N
    workspace_half_m: float = 0.2

    def validate(self) -> StylusParams:
        """self, or ValueError naming the offending field."""
        for name in ("mass_kg", "hand_stiffness_n_per_m", "workspace_half_m", "max_force_n"):
            positive(getattr(self, name), name)
        non_negative(self.hand_damping_ns_per_m, "hand_damping_ns_per_m")
        if self.max_force_n > PHANTOM_MAX_FORCE_N:
            raise ValueError(f"max_force_n must be <= {PHANTOM_MAX_FORCE_N} N (PHANToM limit), "
                             f"got {self.max_force_n!r}")
        return self


class PhantomSim:
    """The simulated stylus, integrated with semi-implicit Euler (v += a·dt, then x += v·dt).

    m·a = k·(h − x) + c·(ḣ − v) + F, with h the hand target in the device frame: the script's
    liver-frame position mapped through `device_map` inverted (the same device→liver map as the
    tool node's, so the mapped stylus follows the script in the liver frame), and F the
    commanded force clamped to `max_force_n` (non-finite → zero). `position` (m), `velocity`
    (m/s) and `time_s` (s since the script's start) are the state; `force` (N) the last applied;
    `energy_to_hand_j` (J) the work the applied forces did on the stylus, Σ F·Δx over every step: the
    energy the device gave the hand, the truth a bridge's passivity observer estimates.

    A step runs at 1 kHz in a node's loop: it works on Python floats (numpy on 3-vectors costs microseconds a
    call); `position`, `velocity` and `force` are numpy copies of that state.
    """

    def __init__(self, trajectory: ScriptedTrajectory, device_map: DeviceMap = DeviceMap(),
                 params: StylusParams = StylusParams()):
        self.trajectory = trajectory
        self.device_map = device_map
        self.params = params.validate()
        self._times, self._points = trajectory.times_s.tolist(), trajectory.positions_m.tolist()
        self._to_device = tuple(map(tuple, device_map.liver_to_device_motion.tolist()))  # Rᵀ/scale
        self._origin = tuple(device_map.translation.tolist())
        self.time_s = 0.0
        self._hand = self._hand_at(0.0)
        self._x, self._v = self._in_workspace(self._hand, (0.0, 0.0, 0.0))
        self._f = (0.0, 0.0, 0.0)
        self.energy_to_hand_j = 0.0

    position = property(lambda self: np.array(self._x), lambda self, value: self._set("_x", value),
                        doc="The stylus tip (m, device frame).")
    velocity = property(lambda self: np.array(self._v), lambda self, value: self._set("_v", value),
                        doc="Its velocity (m/s).")
    force = property(lambda self: np.array(self._f), doc="The force last applied (N).")

    @property
    def tip(self) -> tuple:
        """The stylus tip (m, device frame) as three floats, without a numpy copy."""
        return self._x

    @property
    def pushing(self) -> bool:
        """Whether the last applied force is not zero."""
        return any(self._f)

    def _set(self, name: str, value) -> None:
        setattr(self, name, tuple(float(c) for c in np.asarray(value, dtype=np.float64).reshape(3)))

    def hand_target(self, t: float) -> np.ndarray:
        """Where the hand holds the stylus at time `t` (s), device frame (m)."""
        return np.array(self._hand_at(t))

    def _hand_at(self, t: float) -> tuple:
        """:meth:`hand_target` as floats: the script's position (ScriptedTrajectory.position_at), Rᵀ·(p − t)/scale."""
        times, points = self._times, self._points
        if self.trajectory.loop and times[-1] > 0.0:
            t = t % times[-1]
        if t <= times[0]:
            x, y, z = points[0]
        elif t >= times[-1]:
            x, y, z = points[-1]
        else:
            k = bisect.bisect_right(times, t) - 1
            eased = 0.5 - 0.5 * math.cos(math.pi * (t - times[k]) / (times[k + 1] - times[k]))
            (ax, ay, az), (bx, by, bz) = points[k], points[k + 1]
            x, y, z = ax + eased * (bx - ax), ay + eased * (by - ay), az + eased * (bz - az)
        x, y, z = x - self._origin[0], y - self._origin[1], z - self._origin[2]
        (a, b, c), (d, e, f), (g, h, i) = self._to_device
        return a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z

    def _in_workspace(self, position: tuple, velocity: tuple) -> tuple[tuple, tuple]:
        """(`position` clipped to the workspace box, `velocity` without its outward part at a wall)."""
        half = self.params.workspace_half_m
        if all(-half <= c <= half for c in position):
            return position, velocity
        clipped = tuple(min(max(c, -half), half) for c in position)
        stopped = tuple(0.0 if abs(c) > half and v * c > 0.0 else v for c, v in zip(position, velocity))
        return clipped, stopped

    def _applied(self, commanded_force) -> tuple:
        """The commanded force (N) as the device applies it: clamped by norm to max_force_n, non-finite → zero."""
        fx, fy, fz = (float(c) for c in commanded_force)
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not math.isfinite(norm):
            return 0.0, 0.0, 0.0
        if norm > self.params.max_force_n:
            scale = self.params.max_force_n / norm
            return fx * scale, fy * scale, fz * scale
        return fx, fy, fz

    def step(self, dt: float, commanded_force) -> np.ndarray:
        """Advance `dt` (s) under `commanded_force` (N, device frame); returns the new position (m)."""
        self._step(positive(dt, "dt"), self._applied(commanded_force))
        return self.position

    def _step(self, dt: float, force: tuple) -> None:
        p = self.params
        self._f = force
        hand, hand_next = self._hand, self._hand_at(self.time_s + dt)
        k, c, m = p.hand_stiffness_n_per_m, p.hand_damping_ns_per_m, p.mass_kg
        velocity = tuple(v + dt * (k * (h - x) + c * ((n - h) / dt - v) + f) / m
                         for x, v, h, n, f in zip(self._x, self._v, hand, hand_next, force))
        position, self._v = self._in_workspace(tuple(x + dt * v for x, v in zip(self._x, velocity)), velocity)
        self.energy_to_hand_j += sum(f * (b - a) for f, a, b in zip(force, self._x, position))
        self._x = position
        self.time_s += dt
        self._hand = hand_next

    def advance_to(self, time_s: float, commanded_force, dt: float) -> int:
        """Take fixed steps of `dt` (s) until `time_s` (s) under `commanded_force` (N); returns the steps taken.

        At most MAX_CATCH_UP_STEPS steps: after a longer stall the script skips ahead. No step
        (0) when the stylus is already at `time_s` within dt/2.
        """
        steps = round((time_s - self.time_s) / dt)
        if steps > MAX_CATCH_UP_STEPS:
            self.time_s = time_s - MAX_CATCH_UP_STEPS * dt
            self._hand = self._hand_at(self.time_s)
            steps = MAX_CATCH_UP_STEPS
        force = self._applied(commanded_force)
        for _ in range(steps):
            self._step(dt, force)
        return max(steps, 0)
