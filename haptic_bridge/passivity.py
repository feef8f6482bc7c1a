"""Time-domain passivity at the device port (no ROS): an observer of the energy the rendered force puts into the
hand, and an optional controller that takes out what the rendering generated (Hannaford and Ryu, "Time-domain
passivity control of haptic interfaces", IEEE T-RA 18(1), 2002).

The command F_k (N, device frame) is held from tick k to tick k+1 while the stylus moves by Δx_{k+1} (m, device
frame), so the energy the device gives the hand is

    E_n = Σ_{k<n} F_k · Δx_{k+1}        (J; > 0: the device gave more than it took back).

A passive rendering keeps E_n ≤ 0 at every n (the hand never gets back more than it put in). The controller, when
on, acts before the energy appears: taking the stylus's last motion Δx (its last non-zero one: the tool pose
arrives asynchronously, a tick may see no new sample) as its next, a force F that would give
the hand more than it has put in so far (F·Δx > −E) gets the damping −α·v, v = Δx/T, with

    α = (F·Δx + E)·T/|Δx|²,   at most `max_damping_ns_per_m`,

which leaves F·Δx = −E: the variable damping of time-domain passivity control, with the step ahead predicted
from the last one. The observer then measures what was actually sent.
"""
from __future__ import annotations

import numpy as np


class PassivityObserver:
    """Energy the commands give the hand (module docstring), and the variable damping that takes it out.

    It runs in the 1 kHz tick, on Python floats (numpy on 3-vectors costs microseconds a call): the tick hands it
    the tool tip in the liver frame and :meth:`set_map` the linear part of the liver → device map, Rᵀ/scale, which
    turns a tip's motion into the stylus's."""

    def __init__(self, period_s: float, control: bool = False, max_damping_ns_per_m: float = 0.0):
        self.period_s = period_s
        self.control = control
        self.max_damping_ns_per_m = max_damping_ns_per_m
        self.energy_j = 0.0       # E_n: net energy given to the hand so far
        self.peak_energy_j = 0.0  # the largest E_n so far
        self.damping_ns_per_m = 0.0  # the controller's α at the last tick
        self._to_device = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
        self._tip = None     # the tool tip at the last tick (m, liver frame)
        self._ahead = None   # the stylus's last non-zero motion over a tick (m, device frame): the prediction of the
        #                      next one (the tool pose arrives asynchronously, a tick may see no new sample)
        self._force = (0.0, 0.0, 0.0)

    def set_map(self, liver_to_device: np.ndarray) -> None:
        """The 3×3 matrix taking a motion of the tip (liver frame) to the stylus's (device frame): Rᵀ/scale."""
        self._to_device = tuple(tuple(row) for row in np.asarray(liver_to_device, dtype=float).tolist())

    def observe(self, tip_m: np.ndarray | None) -> None:
        """The tool tip at this tick (m, liver frame; None: not known): add F_{k-1}·Δx to the energy."""
        if tip_m is None:
            self._tip = self._ahead = None
            return
        x, y, z = tip_m.tolist()
        last, self._tip = self._tip, (x, y, z)
        if last is None:
            self._ahead = None
            return
        dx, dy, dz = x - last[0], y - last[1], z - last[2]
        (a, b, c), (d, e, f), (g, h, i) = self._to_device
        step = (a * dx + b * dy + c * dz, d * dx + e * dy + f * dz, g * dx + h * dy + i * dz)
        fx, fy, fz = self._force
        self.energy_j += fx * step[0] + fy * step[1] + fz * step[2]
        if self.energy_j > self.peak_energy_j:
            self.peak_energy_j = self.energy_j
        if dx or dy or dz:
            self._ahead = step

    def damp(self, force_n: np.ndarray) -> np.ndarray:
        """`force_n` (N, device frame), with the controller's damping when it is on and the force would give the
        hand more than it has put in (module docstring)."""
        self.damping_ns_per_m = 0.0
        step = self._ahead
        if not self.control or step is None:
            return force_n
        squared = step[0] * step[0] + step[1] * step[1] + step[2] * step[2]
        fx, fy, fz = force_n.tolist()
        excess = fx * step[0] + fy * step[1] + fz * step[2] + self.energy_j  # J beyond what the hand put in
        if squared <= 0.0 or excess <= 0.0:
            return force_n
        alpha = min(excess * self.period_s / squared, self.max_damping_ns_per_m)
        self.damping_ns_per_m = alpha
        return force_n - (alpha / self.period_s) * np.array(step)

    def commanded(self, force_n: np.ndarray) -> None:
        """The command actually sent at this tick (after the safety chain): held until the next tick."""
        self._force = tuple(force_n.tolist())

    def report(self) -> dict:
        """For diagnostics: E (J), its peak (J), and the controller's state."""
        return {"energy_to_hand_j": self.energy_j, "energy_to_hand_peak_j": self.peak_energy_j,
                "passivity_control": self.control, "passivity_damping_ns_per_m": self.damping_ns_per_m}
