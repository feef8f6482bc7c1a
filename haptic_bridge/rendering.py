"""Rendering the local model at 1 kHz (paper §2.5; P11 of docs/paper.md): glide between physics updates, penalty force,
passivity bounds.

The physics (150 Hz) approximates the surface near the tool by a plane or a sphere
(liver_sim.base.local_model); between its updates the haptic loop renders that primitive analytically.
Everything here works on 3-vectors in metres and newtons, without ROS.
"""
from __future__ import annotations

import math

import numpy as np

from liver_sim.base.checks import non_negative, positive
from liver_sim.base.local_model import LocalModel


def blend(start: LocalModel | None, target: LocalModel, fraction: float) -> LocalModel:
    """The model `fraction` (clipped to 0..1) of the way from `start` to `target`.

    Plane: point and normal interpolated linearly (the normal renormalised); sphere: centre and
    radius; the stiffness K when both carry one; the other fields are the target's. No `start`, an invalid
    model, models of different kinds, or opposite normals give `target`.
    """
    f = min(max(float(fraction), 0.0), 1.0)
    if f >= 1.0 or start is None or start.kind != target.kind or not (start.valid and target.valid):
        return target
    fields = {}
    if start.stiffness_n_per_m is not None and target.stiffness_n_per_m is not None:
        fields["stiffness_n_per_m"] = (start.stiffness_n_per_m
                                       + f * (target.stiffness_n_per_m - start.stiffness_n_per_m))
    if target.kind == "plane":
        normal = (1.0 - f) * start.normal + f * target.normal
        length = math.hypot(*normal)
        if not length > 1e-9:
            return target
        return LocalModel.derived(target, point=start.point + f * (target.point - start.point),
                                  normal=normal / length, **fields)
    return LocalModel.derived(target, centre=start.centre + f * (target.centre - start.centre),
                              radius_m=start.radius_m + f * (target.radius_m - start.radius_m), **fields)


class ModelGlide:
    """The model to render at each tick: a new local model replaces the shown one over `duration_s`.

    The physics moves the local model in 150 Hz steps; rendered at once, each step is a force
    jump of K·(surface motion per frame). Gliding spreads it over the ticks of one physics period
    (at the cost of that much lag in the rendered surface). `duration_s` 0 renders each model at once.
    """

    def __init__(self, duration_s: float):
        self.duration_s = non_negative(duration_s, "duration_s")
        self._target = self._shown = self._start = None
        self._since = 0.0

    def update(self, target: LocalModel | None, now_s: float) -> LocalModel | None:
        """The model to render at `now_s` (s) given the newest `target` (None: no surface near the tool)."""
        if target is not self._target:
            self._target, self._start, self._since = target, self._shown, now_s
        if target is None:
            self._shown = None
        else:
            fraction = (now_s - self._since) / self.duration_s if self.duration_s > 0.0 else 1.0
            self._shown = blend(self._start, target, fraction)
        return self._shown


def contact_force(depth: float, depth_rate: float, direction: np.ndarray,
                  stiffness: float, damping: float) -> np.ndarray:
    """Penalty force (N) on the tool: F = max(0, K·depth + B·depth_rate)·direction, 0 out of contact.

    The bridge's form of the paper's Eq. 3 with the penetration depth (m) in place of
    the interpenetration volume: K = `stiffness` (N/m), B = `damping` (N·s/m),
    `depth_rate` in m/s (positive when going deeper). The clip at 0 means damping
    can slow the surface's push but never turn it into a pull.
    """
    magnitude = stiffness * depth + damping * depth_rate if depth > 0.0 else 0.0
    return max(magnitude, 0.0) * np.asarray(direction, dtype=np.float64)


def passivity_damping_min(stiffness: float, period: float, virtual_damping: float = 0.0) -> float:
    """Smallest damping b (N·s/m) for a passive virtual wall: b > K·T/2 + |B| (Colgate & Schenkel 1997).

    K = `stiffness` (N/m) rendered at sample `period` T (s). In Colgate's result b is
    the damping physically present in the device and B the rendered (virtual) damping,
    which adds to the requirement; with B = 0 this is the K·T/2 bound.
    """
    return (non_negative(stiffness, "stiffness") * positive(period, "period") / 2.0
            + non_negative(abs(virtual_damping), "virtual_damping"))


def max_passive_stiffness(damping: float, period: float, virtual_damping: float = 0.0) -> float:
    """Largest stiffness K (N/m) that damping b (N·s/m) keeps passive at `period` T (s): K < 2·(b − |B|)/T.

    The inverse of :func:`passivity_damping_min`; 0 when |B| ≥ b.
    """
    margin = non_negative(damping, "damping") - non_negative(abs(virtual_damping), "virtual_damping")
    return max(2.0 * margin / positive(period, "period"), 0.0)
