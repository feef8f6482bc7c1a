"""Rendering the local model at 1 kHz (paper §2.5; P11 of docs/paper.md): glide between physics updates, passive model
updates over a delayed link, penalty force, passivity bounds.

The physics (150 Hz) approximates the surface near the tool by a plane or a sphere
(liver_sim.base.local_model); between its updates the haptic loop renders that primitive analytically.
Everything here works on 3-vectors in metres and newtons, without ROS.
"""
from __future__ import annotations

import math

import numpy as np

from liver_sim.base.checks import non_negative, positive
from liver_sim.base.local_model import LocalModel


def capped(model: LocalModel | None, cap_n_per_m: float) -> LocalModel | None:
    """The model the bridge renders for the physics' `model` when it renders no stiffer than `cap_n_per_m` (N/m).

    The physics places its model so that K·d = F, its contact force, d (`depth_m`) the tool's depth in the model at
    the physics' pose. Rendered with K_r = min(K, cap) < K, that pose would feel (K_r/K)·F. So a model whose K is
    above the cap becomes one of stiffness K_r whose surface lies s = d·(K/K_r − 1) further out along the normal
    (plane: point and centre moved by s·normal; sphere, the liver inside: radius + s) and whose `depth_m` is
    d + s = K·d/K_r: at the physics' pose it renders K_r·(d + s) = K·d = F, the physics force, and about that pose
    a spring of the capped K_r, whose passivity the bridge checks. A model with K above the cap and no depth (d = 0:
    no contact force, or a Marker that carries no depth) only takes K_r.

    A model without K, with K at or below the cap, invalid, or None is returned as is (the same object): it renders
    exactly as it did before models carried a depth; so is every model under a cap of 0 (which renders no force).
    A capped model is its own capped model (idempotent).

    The bridge caps each model as it arrives, before the glide (haptic_bridge.tick.BridgeTick.step): the glide then
    moves the rendered surface, at the rendered K, from one update's to the next, which is the step it is there to
    spread; capping the glided model instead would shift a blend of two surfaces by the target's depth, a jump at
    the glide's start.
    """
    stiffness = None if model is None or not model.valid else model.stiffness_n_per_m
    if stiffness is None or stiffness <= cap_n_per_m or not cap_n_per_m > 0.0:
        return model  # (a cap of 0 renders no force: min(K, 0), as the renderer takes it)
    depth = model.depth_m
    if not depth > 0.0:
        return LocalModel.derived(model, stiffness_n_per_m=cap_n_per_m)
    shift = depth * (stiffness / cap_n_per_m - 1.0)
    fields = {"stiffness_n_per_m": cap_n_per_m, "depth_m": depth + shift}
    if model.kind == "plane":
        point = model.point + shift * model.normal
        return LocalModel.derived(model, point=point, centre=point, **fields)
    return LocalModel.derived(model, radius_m=model.radius_m + shift, **fields)


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
    g = 1.0 - f  # floats, not numpy: a blend runs at every 1 kHz tick of a glide
    if target.kind == "plane":
        normal = [g * a + f * b for a, b in zip(start.normal.tolist(), target.normal.tolist())]
        length = math.hypot(*normal)
        if not length > 1e-9:
            return target
        point = [g * a + f * b for a, b in zip(start.point.tolist(), target.point.tolist())]
        return LocalModel.derived(target, point=np.array(point), normal=np.array(normal) / length, **fields)
    centre = [g * a + f * b for a, b in zip(start.centre.tolist(), target.centre.tolist())]
    return LocalModel.derived(target, centre=np.array(centre), radius_m=g * start.radius_m + f * target.radius_m,
                              **fields)


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


def contact_potential(depth_m: float, stiffness_n_per_m: float, max_force_n: float) -> float:
    """Energy (J) a rendered contact stores at penetration `depth_m` (m): ∫ min(K·d, F_max) dd, i.e. ½·K·d² up to
    the clamp's depth F_max/K, then growing by F_max per metre; 0 out of contact."""
    if depth_m <= 0.0 or stiffness_n_per_m <= 0.0:
        return 0.0
    clamp_depth = max_force_n / stiffness_n_per_m
    if depth_m <= clamp_depth:
        return 0.5 * stiffness_n_per_m * depth_m * depth_m
    return max_force_n * depth_m - 0.5 * max_force_n * clamp_depth


def depth_for_potential(energy_j: float, stiffness_n_per_m: float, max_force_n: float) -> float:
    """The penetration (m) at which a contact stores `energy_j` (J): the inverse of :func:`contact_potential`."""
    if energy_j <= 0.0 or stiffness_n_per_m <= 0.0:
        return 0.0
    clamp_depth = max_force_n / stiffness_n_per_m
    if energy_j <= 0.5 * max_force_n * clamp_depth:
        return math.sqrt(2.0 * energy_j / stiffness_n_per_m)
    return energy_j / max_force_n + 0.5 * clamp_depth


def retreated(model: LocalModel, depth_m: float) -> LocalModel:
    """`model` moved back from the tool by `depth_m` (m) along its normal (a plane) or shrunk (a sphere), so that a
    tool `depth_m` deep in `model` just touches it."""
    if model.kind == "plane":
        point = model.point - depth_m * model.normal
        return LocalModel.derived(model, point=point, centre=point)
    return LocalModel.derived(model, radius_m=max(model.radius_m - depth_m, 1e-9))


class PassiveModelUpdate:
    """A passive model update (energy bounding, after Ryu et al. and Mitra and Niemeyer's model-mediated
    telemanipulation): a new local model is rendered only as far as the energy the contact then stores stays
    within what the hand has put into it.

    A model change at the tool's current place changes the energy U the rendered contact stores
    (:func:`contact_potential` of the tool's depth and the model's K). The hand has put `budget_j` = E(t0) − E(t) into
    the contact since it began (haptic_bridge.passivity: t0 the last instant of zero force). A change that lowers U
    (the surface moving away from the tool, a softer K) is rendered at once; one that raises U is rendered as far as
    U stays within the budget, along the way from the shown model to the new one, the rest when the budget or the
    tool allows (a surface moved up to touching the tool stores nothing, so it always may); when the contact already
    stores more than the budget (the estimate lags the hand) the shown model stays. The contact then never holds
    more than the hand put in, so it cannot give the hand back more: E(t) ≤ E(t0) within a contact."""

    def __init__(self, max_force_n: float):
        self.max_force_n = max_force_n
        self.shown: LocalModel | None = None
        self.held_back = False  # the last admitted model stopped short of its target

    def forget(self) -> None:
        """The force went to zero (a restart, stale inputs): the contact is built again from touching, so that the
        soft start that follows stores no energy the hand did not put in."""
        self.shown = None

    def admit(self, target: LocalModel | None, depth, stiffness, budget_j: float) -> LocalModel | None:
        """The model to render this tick, on the way from the one shown to `target`. `depth(model)`: the tool's
        penetration of a model (m) this tick; `stiffness(model)`: the K it is rendered with (N/m); `budget_j`: the
        energy the hand has put into the contact since it began (J)."""
        def energy(model: LocalModel) -> float:
            return contact_potential(depth(model), stiffness(model), self.max_force_n)

        shown = self.shown if self.shown is not None and self.shown.valid else None
        self.held_back = False
        if target is None or not target.valid:
            self.shown = target
            return target
        before, after = (energy(shown) if shown is not None else 0.0), energy(target)
        if after <= max(before, budget_j) and (after <= budget_j or after <= before):
            self.shown = target
            return target
        self.held_back = True
        start = shown if shown is not None and shown.kind == target.kind else retreated(target, depth(target))
        if budget_j <= energy(start):
            self.shown = start  # no way toward the target lowers the energy already stored
            return start
        depth_before, depth_after = depth(start), depth(target)
        wanted = depth_for_potential(budget_j, stiffness(target), self.max_force_n)
        fraction = (wanted - depth_before) / (depth_after - depth_before) if depth_after > depth_before else 0.0
        self.shown = blend(start, target, fraction) if fraction > 0.0 else start
        return self.shown
