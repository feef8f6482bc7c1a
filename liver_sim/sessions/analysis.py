"""Figures of a run from what arrived when: loop rates, period errors, force smoothness (R4 of docs/paper.md,
Fig. 8)."""
from __future__ import annotations

import numpy as np

from haptic_bridge.tick import BridgeTick

#: A force at least this large (N) counts as contact.
CONTACT_FORCE_N = 0.05


def rate_figures(arrival_s: np.ndarray, nominal_hz: float) -> dict:
    """Achieved rate (Hz) and period error p50/p99/max (s) and largest gap (s) of a stream of arrivals."""
    if len(arrival_s) < 3:
        return {"rate_hz": 0.0, "period_error_p50_s": None, "period_error_p99_s": None,
                "period_error_max_s": None, "max_gap_s": None, "samples": int(len(arrival_s))}
    periods = np.diff(arrival_s)
    error = np.abs(periods - 1.0 / nominal_hz)
    return {"rate_hz": float((len(arrival_s) - 1) / (arrival_s[-1] - arrival_s[0])),
            "period_error_p50_s": float(np.percentile(error, 50)),
            "period_error_p99_s": float(np.percentile(error, 99)),
            "period_error_max_s": float(error.max()), "max_gap_s": float(periods.max()),
            "samples": int(len(arrival_s))}


def largest_force_jump_n(forces_n: np.ndarray, contact_force_n: float = CONTACT_FORCE_N,
                         times_s: np.ndarray | None = None, max_period_s: float | None = None,
                         onsets: bool = False) -> float:
    """Largest |F_k − F_{k−1}| (N) between consecutive commands while both are in contact (Fig. 8's harshness);
    with `onsets`, while either is: the steps of touching and leaving the surface count too.

    With `times_s` (when each command was sent) and `max_period_s`, only pairs sent at most
    `max_period_s` apart count: a scheduling gap is not a step of the rendered force.
    """
    if len(forces_n) < 2:
        return 0.0
    touching = np.linalg.norm(forces_n, axis=1) > contact_force_n
    pairs = (touching[1:] | touching[:-1]) if onsets else (touching[1:] & touching[:-1])
    if times_s is not None and max_period_s is not None:
        pairs &= np.diff(times_s) <= max_period_s
    jumps = np.linalg.norm(np.diff(forces_n, axis=0), axis=1)[pairs]
    return float(jumps.max()) if jumps.size else 0.0


def contact_fraction(forces_n: np.ndarray, contact_force_n: float = CONTACT_FORCE_N) -> float:
    """Share of the commands given in contact."""
    return float((np.linalg.norm(forces_n, axis=1) > contact_force_n).mean()) if len(forces_n) else 0.0


def held_wrench_baseline(tick_s: np.ndarray, wrench_arrival_s: np.ndarray, wrench_n: np.ndarray,
                         pose_arrival_s: np.ndarray, bridge_parameters: dict) -> np.ndarray:
    """The (K, 3) commands (N) of Fig. 8's baseline — a bridge with `local_model: none`, which holds the newest
    physics contact force — ticked offline at `tick_s` (s, e.g. when the live bridge sent its commands), with
    the wrenches and tool poses as they arrived (`wrench_arrival_s`, `pose_arrival_s`, s, ascending, on the
    same clock): the node's own BridgeTick with `bridge_parameters`, ages counted from those arrivals. No
    second live bridge needed, hence no second 1 kHz process competing for the cores."""

    tick = BridgeTick(bridge_parameters.replace(local_model="none"))
    newest_wrench = np.searchsorted(wrench_arrival_s, tick_s, side="right") - 1
    newest_pose = np.searchsorted(pose_arrival_s, tick_s, side="right") - 1
    commands = np.zeros((len(tick_s), 3))
    for k, t in enumerate(tick_s):
        w, p = newest_wrench[k], newest_pose[k]
        source, source_age = (wrench_n[w], t - wrench_arrival_s[w]) if w >= 0 else (None, np.inf)
        commands[k] = tick.step(t, None, t - pose_arrival_s[p] if p >= 0 else np.inf, source, source_age)
    return commands


def fig8_figures(with_local_model_n: np.ndarray, without_local_model_n: np.ndarray, times_s: np.ndarray | None = None,
                 max_period_s: float | None = None) -> dict:
    """Fig. 8 as numbers: the largest change (N) between consecutive commands in contact — at either of the
    two, so touching and leaving the surface count (:func:`largest_force_jump_n` with onsets) — with and
    without the local model, and their ratio, the smoothness ratio (without / with; None when nothing
    changed with the local model); the same with both commands in contact (`…_steady`), which leaves out
    the held force's steps onto and off the surface.  `times_s`/`max_period_s` as in largest_force_jump_n."""
    figures = {}
    for suffix, onsets in (("", True), ("_steady", False)):
        with_lm = largest_force_jump_n(with_local_model_n, times_s=times_s, max_period_s=max_period_s, onsets=onsets)
        without = largest_force_jump_n(without_local_model_n, times_s=times_s, max_period_s=max_period_s,
                                       onsets=onsets)
        figures.update({f"largest_jump_with_local_model{suffix}_n": with_lm,
                        f"largest_jump_without_local_model{suffix}_n": without,
                        f"smoothness_ratio{suffix}": without / with_lm if with_lm > 0 else None})
    return figures


def fig8_line(figures: dict) -> str:
    """Fig. 8's figures (analysis.fig8_figures) in one line, against the target ratio of 5."""
    ratio = figures["smoothness_ratio"]
    return (f"largest change between consecutive 1 ms commands in contact (touching and leaving included): "
            f"{figures['largest_jump_with_local_model_n']:.4f} N with the local model, "
            f"{figures['largest_jump_without_local_model_n']:.4f} N without (physics force held): "
            f"smoothness ratio {'n/a' if ratio is None else f'{ratio:.1f}x'} (target >= 5)")
