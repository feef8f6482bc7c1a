"""What stands between the force computation and the haptic device (docs/contract.md, "Haptic safety").

The device never receives NaN/inf, a force above `max_force`, a change faster
than the rate limit, or a force computed from stale data: when the local model
or the tool pose outlives its lifetime the force ramps to exactly zero within
`ramp_time_s` and stays there until fresh data arrive. It then rises again over
the soft-start time (`rise_time_s`), as it does after start and after every
restart (a stall or an error of the loop, a new device map).
"""
from __future__ import annotations

import math

import numpy as np

from liver_sim.base.checks import positive

#: The PHANToM's peak force (N); no configuration may exceed it.
PHANTOM_MAX_FORCE_N = 3.3
#: Default force clamp (N), docs/contract.md.
DEFAULT_MAX_FORCE_N = 2.0
#: Gains within this of 0 or 1 are snapped there, so ramps end exactly.
_GAIN_SNAP = 1e-9
#: A clamped force is scaled to this fraction below the clamp, so that no rounding of its norm, here or
#: at the device, exceeds the clamp.
_CLAMP_MARGIN = 1e-12


def clamped(fx: float, fy: float, fz: float, max_force: float) -> tuple[float, float, float]:
    """(fx, fy, fz)·min(1, max_force/|F|) in N, its norm never above max_force however it is rounded; any
    non-finite component → zero. Floats: it runs several times per 1 kHz tick."""
    norm = math.hypot(fx, fy, fz)  # no overflow for components near the float limit; nan or inf if any is
    if not math.isfinite(norm):
        return 0.0, 0.0, 0.0
    if norm > max_force:
        scale = max_force / norm * (1.0 - _CLAMP_MARGIN)
        return fx * scale, fy * scale, fz * scale
    return fx, fy, fz


def clamp_norm(force: np.ndarray, max_force: float) -> np.ndarray:
    """:func:`clamped` of a (3,) force (N), as a new array."""
    return np.array(clamped(*(float(c) for c in force), max_force))


class RateLimiter:
    """Limits the change of the force to `max_rate_n_per_s` per second of the clock the ticks give: |F_k − F_{k−1}|
    ≤ max_rate_n_per_s·(t_k − t_{k−1}), moving towards the target; a burst of ticks microseconds apart (a loop
    catching up) changes it by no more than the time they span allows. Without tick times, and for the first
    tick after a reset, the elapsed time is `period_s`.

    A non-finite target counts as zero, so the state stays finite.
    """

    def __init__(self, max_rate_n_per_s: float, period_s: float):
        self.max_rate_n_per_s = positive(max_rate_n_per_s, "max_rate_n_per_s")
        self.period_s = positive(period_s, "period_s")
        self.reset()

    @property
    def last(self) -> np.ndarray:
        """The force it sent last (N)."""
        return np.array(self._last)

    @last.setter
    def last(self, force) -> None:
        self._last = tuple(float(c) for c in force)

    def reset(self) -> None:
        """Restart from zero force."""
        self._last = (0.0, 0.0, 0.0)
        self.last_s = None

    def step(self, target: np.ndarray, now_s: float | None = None) -> np.ndarray:
        """The force (N) closer to `target` at tick time `now_s` (s): F_{k−1} + Δ, |Δ| ≤ max_rate_n_per_s·elapsed."""
        return np.array(self.step_floats(*(float(c) for c in target), now_s))

    def step_floats(self, tx: float, ty: float, tz: float, now_s: float | None = None) -> tuple[float, float, float]:
        """:meth:`step` on floats."""
        if now_s is None or self.last_s is None:
            elapsed = self.period_s
        else:
            elapsed = min(max(now_s - self.last_s, 0.0), 1.0)
        self.last_s = now_s
        lx, ly, lz = self._last
        dx, dy, dz = tx - lx, ty - ly, tz - lz
        change = math.hypot(dx, dy, dz)
        if not math.isfinite(change):
            dx, dy, dz, change = -lx, -ly, -lz, math.hypot(lx, ly, lz)
        max_change = self.max_rate_n_per_s * elapsed
        if change > max_change:
            scale = max_change / change
            dx, dy, dz = dx * scale, dy * scale, dz * scale
        self._last = (lx + dx, ly + dy, lz + dz)
        return self._last


class Watchdog:
    """Force gain in [0, 1] from the age of the newest local model and tool pose.

    Called once per tick of `period_s`. Fresh (both ages ≤ their lifetime): the
    gain rises by `period_s`/`rise_time_s` per tick up to 1 (soft start; `rise_time_s`
    defaults to `ramp_time_s`); stale (either age beyond its lifetime, NaN or inf):
    it falls by `period_s`/`ramp_time_s` to exactly 0, reached within
    ceil(`ramp_time_s`/`period_s`) ticks, and stays there.
    `state` is 'ok', 'ramping_down', 'stale' or 'ramping_up' (for diagnostics);
    it starts 'stale', with gain 0, until fresh data arrive; :meth:`restart` returns there.
    """

    def __init__(self, lifetime_s: float = 0.05, ramp_time_s: float = 0.01, period_s: float = 0.001,
                 rise_time_s: float | None = None):
        self.period_s = positive(period_s, "period_s")
        self.configure(lifetime_s, ramp_time_s, ramp_time_s if rise_time_s is None else rise_time_s)
        self.restart()

    def configure(self, lifetime_s: float, ramp_time_s: float, rise_time_s: float) -> None:
        """New lifetime, ramp-down and soft-start times (s), effective from the next tick."""
        self.lifetime_s = positive(lifetime_s, "lifetime_s")
        self.ramp_time_s = positive(ramp_time_s, "ramp_time_s")
        self.rise_time_s = positive(rise_time_s, "rise_time_s")
        self._down = self.period_s / self.ramp_time_s
        self._up = self.period_s / self.rise_time_s

    def restart(self) -> None:
        """Gain 0, state 'stale': the force starts again from zero with a soft start."""
        self.gain = 0.0
        self.state = "stale"

    def update(self, model_age_s: float, pose_age_s: float, model_lifetime_s: float | None = None) -> float:
        """Advance one tick and return the gain.

        `model_lifetime_s` is the lifetime the local model carries (s); None uses
        `lifetime_s`, which always applies to the tool pose.
        """
        model_lifetime = self.lifetime_s if model_lifetime_s is None else model_lifetime_s
        fresh = model_age_s <= model_lifetime and pose_age_s <= self.lifetime_s
        gain = self.gain + self._up if fresh else self.gain - self._down
        if gain >= 1.0 - _GAIN_SNAP:
            self.gain, self.state = 1.0, "ok" if fresh else "ramping_down"
        elif gain <= _GAIN_SNAP:
            self.gain, self.state = 0.0, "ramping_up" if fresh else "stale"
        else:
            self.gain, self.state = gain, "ramping_up" if fresh else "ramping_down"
        return self.gain


class SafeForceOutput:
    """The last stage before the device: F_out = finite(clamp(rate_limit(clamp(gain·F)))).

    `max_force` (N) must lie in (0, 3.3] (PHANToM limit; default 2.0).
    The target is clamped before the rate limiter so the limiter's state never
    winds up above the clamp (releasing a stiff contact is not delayed); the
    final clamp and finiteness check guard the wire. `max_rate_n_per_s`·`ramp_time_s`
    must be ≥ `max_force` so the limiter can follow the watchdog's ramp to zero.
    """

    def __init__(self, max_force: float = DEFAULT_MAX_FORCE_N, max_rate_n_per_s: float = 400.0,
                 period_s: float = 0.001, lifetime_s: float = 0.05, ramp_time_s: float = 0.01,
                 soft_start_s: float | None = None):
        self.watchdog = Watchdog(lifetime_s, ramp_time_s, period_s, soft_start_s)
        self.limiter = RateLimiter(max_rate_n_per_s, period_s)
        self.configure(max_force, max_rate_n_per_s, lifetime_s, ramp_time_s,
                       ramp_time_s if soft_start_s is None else soft_start_s)

    def configure(self, max_force: float, max_rate_n_per_s: float, lifetime_s: float, ramp_time_s: float,
                  soft_start_s: float) -> None:
        """Check and take new limits, effective from the next :meth:`step`; ValueError naming the first bad
        one leaves the old limits in place. A lower clamp bounds the very next command."""
        max_force = positive(max_force, "max_force")
        if max_force > PHANTOM_MAX_FORCE_N:
            raise ValueError(f"max_force must be <= {PHANTOM_MAX_FORCE_N} N (PHANToM limit), got {max_force!r}")
        max_rate = positive(max_rate_n_per_s, "max_rate_n_per_s")
        if max_rate * positive(ramp_time_s, "ramp_time_s") < max_force * (1.0 - 1e-9):
            raise ValueError(f"max_rate_n_per_s must be >= max_force/ramp_time_s = "
                             f"{max_force / ramp_time_s:g} N/s so the force can reach 0 "
                             f"within ramp_time_s, got {max_rate_n_per_s!r}")
        self.watchdog.configure(lifetime_s, ramp_time_s, soft_start_s)
        self.max_force = max_force
        self.limiter.max_rate_n_per_s = max_rate
        self.limiter.last = clamp_norm(self.limiter.last, max_force)  # no wind-up above a lowered clamp

    def restart(self) -> None:
        """Zero force now, then a soft start once the inputs are fresh (after a stall or an error)."""
        self.watchdog.restart()
        self.limiter.reset()

    @property
    def state(self) -> str:
        """The watchdog state: 'ok', 'ramping_down', 'stale' or 'ramping_up'."""
        return self.watchdog.state

    def step(self, force, model_age_s: float, pose_age_s: float,
             model_lifetime_s: float | None = None, now_s: float | None = None) -> np.ndarray:
        """The (3,) force (N) to send at tick time `now_s` (s; None: one nominal period after the last) for the
        requested `force` (N, three numbers); see :class:`Watchdog` for the ages and :class:`RateLimiter` for the
        times."""
        gain = self.watchdog.update(model_age_s, pose_age_s, model_lifetime_s)
        if gain == 0.0:
            self.limiter.reset()
            return np.zeros(3)
        fx, fy, fz = clamped(*(float(c) for c in force), self.max_force)
        return np.array(clamped(*self.limiter.step_floats(fx * gain, fy * gain, fz * gain, now_s), self.max_force))
