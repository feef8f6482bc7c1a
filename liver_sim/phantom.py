"""The PHANToM side of the loop without ROS (P12): a simulated stylus, and device samples → liver frame.

`PhantomSim` stands in for the device: a point mass at the stylus tip held by a virtual hand — a
spring-damper pulling it towards a hand target that plays a `tool_scripts` script — and pushed
by the commanded force, clamped as the real device does. `DeviceToLiver` turns device samples
(frame `phantom_base`) into tool poses in the liver frame. Metres, kilograms, seconds, newtons.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic_bridge.local_model import FrameMap
from haptic_bridge.safety import PHANTOM_MAX_FORCE_N, clamp_norm
from liver_sim.rotations import quaternion_to_matrix
from liver_sim.tool_scripts import ScriptedTrajectory

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
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.hand_damping_ns_per_m) and self.hand_damping_ns_per_m >= 0.0):
            raise ValueError(f"hand_damping_ns_per_m must be finite and >= 0, got {self.hand_damping_ns_per_m!r}")
        if self.max_force_n > PHANTOM_MAX_FORCE_N:
            raise ValueError(f"max_force_n must be <= {PHANTOM_MAX_FORCE_N} N (PHANToM limit), "
                             f"got {self.max_force_n!r}")
        return self


class PhantomSim:
    """The simulated stylus, integrated with semi-implicit Euler (v += a·dt, then x += v·dt).

    m·a = k·(h − x) + c·(ḣ − v) + F, with h the hand target in the device frame: the script's
    liver-frame position mapped through `frame_map` inverted (the same device→liver map as the
    tool node's, so the mapped stylus follows the script in the liver frame), and F the
    commanded force clamped to `max_force_n` (non-finite → zero). `position` (m), `velocity`
    (m/s) and `time_s` (s since the script's start) are the state; `force` (N) the last applied.
    """

    def __init__(self, trajectory: ScriptedTrajectory, frame_map: FrameMap = FrameMap(),
                 params: StylusParams = StylusParams()):
        self.trajectory = trajectory
        self.frame_map = frame_map
        self.params = params.validate()
        self.time_s = 0.0
        self._hand = self.hand_target(0.0)
        self.position = self._in_workspace(self._hand.copy(), np.zeros(3))
        self.velocity = np.zeros(3)
        self.force = np.zeros(3)

    def hand_target(self, t: float) -> np.ndarray:
        """Where the hand holds the stylus at time `t` (s), device frame (m)."""
        return self.frame_map.liver_to_device(self.trajectory.position_at(t))

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
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be finite and > 0 s, got {dt!r}")
        p = self.params
        self.force = clamp_norm(commanded_force, p.max_force_n)
        hand_next = self.hand_target(self.time_s + dt)
        hand_velocity = (hand_next - self._hand) / dt
        acceleration = (p.hand_stiffness_n_per_m * (self._hand - self.position)
                        + p.hand_damping_ns_per_m * (hand_velocity - self.velocity) + self.force) / p.mass_kg
        self.velocity = self.velocity + dt * acceleration
        self.position = self._in_workspace(self.position + dt * self.velocity, self.velocity)
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


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a 3×3 rotation matrix (Shepperd's method, w ≥ 0)."""
    r = rotation
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s]
    q = np.array(q)
    return q if q[3] >= 0.0 else -q


@dataclass(frozen=True)
class DeviceToLiver:
    """Device samples (device frame, m) → tool poses in the liver frame, refusing implausible ones.

    A sample farther than `workspace_radius_m` (m) from the device origin, or with a non-finite
    or zero component, raises ValueError saying why.
    """

    frame_map: FrameMap
    workspace_radius_m: float = 0.5

    def pose(self, position, orientation_xyzw) -> tuple[np.ndarray, np.ndarray]:
        """(liver position (m), liver orientation (x, y, z, w)) of one device sample."""
        position = np.asarray(position, dtype=np.float64)
        if not np.isfinite(position).all():
            raise ValueError(f"device position {position.tolist()} is not finite")
        distance = float(np.linalg.norm(position))
        if distance > self.workspace_radius_m:
            raise ValueError(f"device position {np.round(position, 4).tolist()} m is {distance:.3g} m from the "
                             f"device origin, beyond workspace_radius_m={self.workspace_radius_m:g}")
        rotation = self.frame_map.rotation @ quaternion_to_matrix(orientation_xyzw)
        return self.frame_map.device_to_liver(position), matrix_to_quaternion(rotation)
