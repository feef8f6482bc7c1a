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
    """Energy the commands give the hand (module docstring), and the variable damping that takes it out."""

    def __init__(self, period_s: float, control: bool = False, max_damping_ns_per_m: float = 0.0):
        self.period_s = period_s
        self.control = control
        self.max_damping_ns_per_m = max_damping_ns_per_m
        self.energy_j = 0.0       # E_n: net energy given to the hand so far
        self.peak_energy_j = 0.0  # the largest E_n so far
        self.damping_ns_per_m = 0.0  # the controller's α at the last tick
        self._position = None  # the stylus at the last tick (m)
        self._step = None      # its motion over the last tick (m)
        self._ahead = None     # the last non-zero motion: the prediction of the next tick's (the tool pose arrives
        #                        asynchronously, so a tick may see no new sample and the next two)
        self._force = np.zeros(3)

    def observe(self, position_m: np.ndarray | None) -> None:
        """The stylus at this tick (m, device frame; None: not known): add F_{k-1}·Δx to the energy."""
        self._step = None if position_m is None or self._position is None else position_m - self._position
        self._position = position_m
        if self._step is None:
            self._ahead = None
        else:
            self.energy_j += float(self._force @ self._step)
            self.peak_energy_j = max(self.peak_energy_j, self.energy_j)
            if self._step.any():
                self._ahead = self._step

    def damp(self, force_n: np.ndarray) -> np.ndarray:
        """`force_n` (N, device frame), with the controller's damping when it is on and the force would give the
        hand more than it has put in (module docstring)."""
        self.damping_ns_per_m = 0.0
        step = self._ahead
        if not self.control or step is None:
            return force_n
        squared = float(step @ step)
        excess = float(force_n @ step) + self.energy_j  # J beyond what the hand put in, over a tick like the last
        if squared <= 0.0 or excess <= 0.0:
            return force_n
        alpha = min(excess * self.period_s / squared, self.max_damping_ns_per_m)
        self.damping_ns_per_m = alpha
        return force_n - alpha * step / self.period_s

    def commanded(self, force_n: np.ndarray) -> None:
        """The command actually sent at this tick (after the safety chain): held until the next tick."""
        self._force = force_n

    def report(self) -> dict:
        """For diagnostics: E (J), its peak (J), and the controller's state."""
        return {"energy_to_hand_j": self.energy_j, "energy_to_hand_peak_j": self.peak_energy_j,
                "passivity_control": self.control, "passivity_damping_ns_per_m": self.damping_ns_per_m}
