"""The simulated PHANToM without ROS (paper P12, docs/paper.md); liver_sim.phantom.parameters holds the
parameters of the `phantom_sim` node that runs it.

`PhantomSim` stands in for the device: a point mass at the stylus tip held by a virtual hand — a
spring-damper pulling it towards a hand target that plays a `tool_scripts` script — and pushed
by the commanded force, clamped as the real device does. Metres, kilograms, seconds, newtons.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic_bridge.safety import PHANTOM_MAX_FORCE_N, clamp_norm
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
    """

    def __init__(self, trajectory: ScriptedTrajectory, device_map: DeviceMap = DeviceMap(),
                 params: StylusParams = StylusParams()):
        self.trajectory = trajectory
        self.device_map = device_map
        self.params = params.validate()
        self.time_s = 0.0
        self._hand = self.hand_target(0.0)
        self.position = self._in_workspace(self._hand.copy(), np.zeros(3))
        self.velocity = np.zeros(3)
        self.force = np.zeros(3)
        self.energy_to_hand_j = 0.0

    def hand_target(self, t: float) -> np.ndarray:
        """Where the hand holds the stylus at time `t` (s), device frame (m)."""
        return self.device_map.liver_to_device(self.trajectory.position_at(t))

    def _in_workspace(self, position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """`position` clipped to the workspace box; `velocity` loses its outward part at a wall (in place)."""
        half = self.params.workspace_half_m
        outside = np.abs(position) > half
        if outside.any():
            velocity[outside & (np.sign(velocity) == np.sign(position))] = 0.0
            position = np.clip(position, -half, half)
        return position

    def step(self, dt: float, commanded_force) -> np.ndarray:
        """Advance `dt` (s) under `commanded_force` (N, device frame); returns the new position (m)."""
        dt = positive(dt, "dt")
        p = self.params
        self.force = clamp_norm(commanded_force, p.max_force_n)
        hand_next = self.hand_target(self.time_s + dt)
        hand_velocity = (hand_next - self._hand) / dt
        acceleration = (p.hand_stiffness_n_per_m * (self._hand - self.position)
                        + p.hand_damping_ns_per_m * (hand_velocity - self.velocity) + self.force) / p.mass_kg
        self.velocity = self.velocity + dt * acceleration
        position = self._in_workspace(self.position + dt * self.velocity, self.velocity)
        self.energy_to_hand_j += float(self.force @ (position - self.position))
        self.position = position
        self.time_s += dt
        self._hand = hand_next
        return self.position

    def advance_to(self, time_s: float, commanded_force, dt: float) -> int:
        """Take fixed steps of `dt` (s) until `time_s` (s) under `commanded_force` (N); returns the steps taken.

        At most MAX_CATCH_UP_STEPS steps: after a longer stall the script skips ahead. No step
        (0) when the stylus is already at `time_s` within dt/2.
        """
        steps = round((time_s - self.time_s) / dt)
        if steps > MAX_CATCH_UP_STEPS:
            self.time_s = time_s - MAX_CATCH_UP_STEPS * dt
            self._hand = self.hand_target(self.time_s)
            steps = MAX_CATCH_UP_STEPS
        for _ in range(steps):
            self.step(dt, commanded_force)
        return max(steps, 0)
