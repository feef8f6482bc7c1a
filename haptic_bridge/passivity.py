"""Time-domain passivity at the device port (no ROS): the energy the rendered force gives the hand, a controller that
takes out what the rendering generated (Hannaford and Ryu, "Time-domain passivity control of haptic interfaces",
IEEE T-RA 18(1), 2002), and the windowed judgement of a run.

**Energy.** The command in effect at the device, F(t) (N, device frame), works on the stylus as it moves:

    E(t) = ∫ F·dx        (J; > 0: the device gave the hand more than it took back).

A device measures it on its own motion (phantom_sim: the force it applied times each integration step's
displacement). The bridge estimates it (:class:`PassivityObserver`) from the stylus samples it receives: the
interval between two samples (by their stamps) is paired with the command in effect at the device then, the
newest one sent at or before the later stamp minus the one-way latency h (h: the samples' arrival minus their
stamp, smoothed, taken as the way back too). Stamps and the bridge's clock must be one clock (the system clock).

**Generated energy.** Pressing into a passive contact the hand puts energy in (E falls); the contact may give back
what it stored (E rises). Between t1 and t2 the rendering generated at least

    G(t1, t2) = E(t2) − E(t1) − S(t1),    S(t1) = max(0, E(t0) − E(t1)),

S(t1) bounding what the contact stores at t1 by what the hand put in since the contact began (t0: the last tick
with zero force, when nothing is stored). With M(t) = max(E(t), E(t0)), G(t1, t2) = E(t2) − M(t1). A run is
**passive** when no window of WINDOW_S holds a G above GENERATED_LIMIT_J (:func:`max_generated_energy`): energy
the hand put in early cannot hide energy generated later, and a contact giving back its own is not generation.

**Controller** (`control`). When the current contact has given the hand more than the hand put in since it began
(E − E(t0) > 0), the damping −α·v joins the command, v the stylus velocity measured from the two newest samples:

    α = (E − E(t0)) / (T·|v|²),   at most `max_damping_ns_per_m`,

which dissipates that excess over the next period T. A still stylus (v = 0) gets no controller force.
"""
from __future__ import annotations

import threading
from collections import deque

import numpy as np

#: The window (s) of the passivity judgement.
WINDOW_S = 0.5
#: Largest energy (J) a passive rendering may generate in a window: a 1 N force over 0.5 mm.
GENERATED_LIMIT_J = 0.0005
#: Smoothing of the measured one-way latency (fraction of each new sample's).
LATENCY_SMOOTHING = 0.05
#: Commands kept for pairing with samples: 2 s at 1 kHz, far beyond any latency the watchdog lets render.
COMMANDS_KEPT = 2000


def max_generated_energy(energy_j: np.ndarray, episode_energy_j: np.ndarray, window_samples: int) -> np.ndarray:
    """For each sample i, the largest G(t1, t_i) (J) over the t1 of the `window_samples` samples up to i (module
    docstring): E_i − min over the window of max(E, E(t0)). `episode_energy_j`: E(t0) at each sample."""
    energy = np.asarray(energy_j, dtype=np.float64)
    held = np.maximum(energy, np.asarray(episode_energy_j, dtype=np.float64))
    if energy.size == 0:
        return energy
    width = max(1, int(window_samples))
    padded = np.concatenate([np.full(width - 1, held[0]), held])
    lowest = np.lib.stride_tricks.sliding_window_view(padded, width).min(axis=1)
    return energy - lowest


class GenerationMonitor:
    """The largest generated energy over WINDOW_S windows of a running loop (module docstring).

    The loop calls :meth:`record` each tick (E and whether the force is non-zero); a slower thread calls
    :meth:`update`, which folds the samples recorded since into `max_generated_j` (and `at_s`, the loop time of
    that window's end)."""

    def __init__(self, period_s: float, window_s: float = WINDOW_S):
        self.window_samples = max(1, round(window_s / period_s))
        self.max_generated_j = 0.0
        self.at_s = float("nan")
        self._lock = threading.Lock()
        self._episode_energy_j = 0.0
        self._times: list[float] = []
        self._energy: list[float] = []
        self._episode: list[float] = []
        self._seen = 0  # samples at the front of the lists already judged (kept as the next windows' history)

    def record(self, time_s: float, energy_j: float, in_contact: bool) -> None:
        if not in_contact:
            self._episode_energy_j = energy_j
        with self._lock:
            self._times.append(time_s)
            self._energy.append(energy_j)
            self._episode.append(self._episode_energy_j)
            overfull = len(self._times) > 8 * self.window_samples
        if overfull:  # nobody updated for a long time
            self.update()

    def update(self) -> float:
        """Judge the samples recorded since the last update; the largest G so far (J)."""
        with self._lock:
            times, energy, episode, seen = self._times, self._energy, self._episode, self._seen
            keep = self.window_samples - 1
            self._times, self._energy, self._episode = times[-keep:], energy[-keep:], episode[-keep:]
            self._seen = len(self._times)
        if len(times) <= seen:
            return self.max_generated_j
        generated = max_generated_energy(np.array(energy), np.array(episode), self.window_samples)[seen:]
        i = int(np.argmax(generated))
        if generated[i] > self.max_generated_j:
            self.max_generated_j, self.at_s = float(generated[i]), times[seen + i]
        return self.max_generated_j


class PassivityObserver:
    """The bridge's estimate of E from the stylus samples and its commands, and the controller (module docstring).

    It runs in the 1 kHz tick on Python floats (numpy on 3-vectors costs microseconds a call). :meth:`sample` takes
    each stylus sample (device frame), :meth:`damp` adds the controller's damping to a force, :meth:`commanded`
    takes each command sent."""

    def __init__(self, period_s: float, control: bool = False, max_damping_ns_per_m: float = 0.0):
        self.period_s = period_s
        self.control = control
        self.max_damping_ns_per_m = max_damping_ns_per_m
        self.energy_j = 0.0             # E: net energy given to the hand so far (estimate)
        self.episode_energy_j = 0.0     # E(t0): E when the force was last zero
        self.damping_ns_per_m = 0.0     # the controller's α at the last tick
        self.latency_s = None           # h: smoothed arrival − stamp of the samples
        self.monitor = GenerationMonitor(period_s)
        self._sent = deque(maxlen=COMMANDS_KEPT)  # (sent s, fx, fy, fz), oldest first
        self._effective = (0.0, 0.0, 0.0)         # the command in effect at the device at the last sample
        self._last = None                         # (stamp s, x, y, z) of the last sample
        self._velocity = (0.0, 0.0, 0.0)          # m/s, device frame, between the two newest samples

    def sample(self, stamp_s: float, arrival_s: float, position_m) -> None:
        """A stylus sample: its stamp and arrival (s, one clock), its position (m, device frame). A sample stamped
        before the last one (the device's clock stepped back) starts a new reference: motion and latency anew."""
        x, y, z = position_m
        last = self._last
        if last is not None and stamp_s == last[0]:
            return  # the same sample again
        if last is not None and stamp_s < last[0]:  # the device's clock stepped back: a new reference, not a freeze
            self.forget_motion()
            self.latency_s = last = None
        latency = max(arrival_s - stamp_s, 0.0)
        self.latency_s = latency if self.latency_s is None else (
            self.latency_s + LATENCY_SMOOTHING * (latency - self.latency_s))
        self._last = (stamp_s, x, y, z)
        if last is None:
            return
        cutoff = stamp_s - self.latency_s
        sent = self._sent
        while sent and sent[0][0] <= cutoff:
            self._effective = sent.popleft()[1:]
        dx, dy, dz = x - last[1], y - last[2], z - last[3]
        fx, fy, fz = self._effective
        self.energy_j += fx * dx + fy * dy + fz * dz
        dt = stamp_s - last[0]
        self._velocity = (dx / dt, dy / dt, dz / dt)

    def forget_motion(self) -> None:
        """No stylus samples (stale, or a new device map): the next sample starts a new motion."""
        self._last = None
        self._velocity = (0.0, 0.0, 0.0)

    def damp(self, force_n: np.ndarray) -> np.ndarray:
        """`force_n` (N, device frame) with the controller's damping −α·v when it is on and the contact has given
        back more than the hand put in since it began."""
        self.damping_ns_per_m = 0.0
        excess = self.energy_j - self.episode_energy_j
        if not self.control or excess <= 0.0:
            return force_n
        vx, vy, vz = self._velocity
        squared = vx * vx + vy * vy + vz * vz
        if squared <= 0.0:
            return force_n
        alpha = min(excess / (self.period_s * squared), self.max_damping_ns_per_m)
        self.damping_ns_per_m = alpha
        return force_n - alpha * np.array(self._velocity)

    def commanded(self, sent_s: float, force_n: np.ndarray) -> None:
        """The command sent at `sent_s` (s, the samples' clock), after the safety chain."""
        fx, fy, fz = force_n.tolist()
        self._sent.append((sent_s, fx, fy, fz))
        in_contact = bool(fx or fy or fz)
        if not in_contact:
            self.episode_energy_j = self.energy_j
        self.monitor.record(sent_s, self.energy_j, in_contact)

    def report(self) -> dict:
        """For diagnostics: E (J), the largest generated energy in a window (J), the controller's state."""
        return {"energy_to_hand_j": self.energy_j, "energy_generated_max_j": self.monitor.update(),
                "passivity_control": self.control, "passivity_damping_ns_per_m": self.damping_ns_per_m,
                "device_latency_s": self.latency_s if self.latency_s is not None else float("nan")}
