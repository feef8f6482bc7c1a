"""The local model of the touched surface and its 1 kHz force (paper §2.5, P10–P11).

The physics (150 Hz) approximates the surface near the tool by a plane or a
sphere; between its updates the haptic loop renders that primitive analytically.
Everything here works on 3-vectors in metres and newtons, without ROS.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from liver_sim.rotations import quaternion_to_matrix

#: A tip closer than this (m) to a sphere model's centre gets the fallback direction +z.
CENTRE_EPS_M = 1e-12
_UP = np.array([0.0, 0.0, 1.0])
_UP.setflags(write=False)


def _vector3(value, name: str) -> np.ndarray:
    """A finite, read-only float64 3-vector, or ValueError naming `name`."""
    vec = np.array(value, dtype=np.float64)
    if vec.shape != (3,) or not np.isfinite(vec).all():
        raise ValueError(f"{name} must be a finite 3-vector, got {value!r}")
    vec.setflags(write=False)
    return vec


@dataclass(frozen=True, eq=False)
class PlaneModel:
    """Plane through `point` (m) with outward unit `normal`; the liver is on the −normal side."""

    point: np.ndarray
    normal: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "point", _vector3(self.point, "PlaneModel.point"))
        normal = _vector3(self.normal, "PlaneModel.normal")
        length = float(np.linalg.norm(normal))
        if not length > 0.0:
            raise ValueError(f"PlaneModel.normal must be non-zero, got {self.normal!r}")
        normal = normal / length
        normal.setflags(write=False)
        object.__setattr__(self, "normal", normal)


@dataclass(frozen=True, eq=False)
class SphereModel:
    """Sphere of `radius` (m) about `centre` (m); the liver is inside it."""

    centre: np.ndarray
    radius: float

    def __post_init__(self):
        object.__setattr__(self, "centre", _vector3(self.centre, "SphereModel.centre"))
        radius = float(self.radius)
        if not (np.isfinite(radius) and radius > 0.0):
            raise ValueError(f"SphereModel.radius must be finite and > 0 m, got {self.radius!r}")
        object.__setattr__(self, "radius", radius)


def penetration(model: PlaneModel | SphereModel, tip: np.ndarray,
                tool_radius: float = 0.0) -> tuple[float, np.ndarray]:
    """Depth (m, ≥ 0) of the tool sphere (centre `tip`, radius `tool_radius` m) into `model`,
    and the unit direction in which the surface pushes the tool.

    The paper minimises the tip–surface distance with Lagrange multipliers (§2.5);
    for a plane and a sphere that minimisation has these closed forms:

    - plane:  depth = max(0, r_tool − (tip − point)·n),            direction = n;
    - sphere: depth = max(0, R + r_tool − |tip − centre|),         direction = (tip − centre)/|tip − centre|
      (+z when the tip is within CENTRE_EPS_M of the centre, where every direction is equally short).

    A non-finite `tip` gives a non-finite result; the safety stage turns that into zero force.
    """
    if isinstance(model, PlaneModel):
        depth = tool_radius - float(np.dot(tip - model.point, model.normal))
        return max(depth, 0.0), model.normal
    offset = tip - model.centre
    distance = float(np.linalg.norm(offset))
    direction = offset / distance if distance > CENTRE_EPS_M else _UP
    return max(model.radius + tool_radius - distance, 0.0), direction


def blend(start: PlaneModel | SphereModel | None, target: PlaneModel | SphereModel,
          fraction: float) -> PlaneModel | SphereModel:
    """The model `fraction` (clipped to 0..1) of the way from `start` to `target`.

    Plane: point and normal interpolated linearly (the normal renormalised); sphere: centre and
    radius. No `start`, models of different kinds, or opposite normals give `target`.
    """
    f = min(max(float(fraction), 0.0), 1.0)
    if f >= 1.0 or start is None or type(start) is not type(target):
        return target
    if isinstance(target, PlaneModel):
        normal = (1.0 - f) * start.normal + f * target.normal
        if not np.linalg.norm(normal) > 1e-9:
            return target
        return PlaneModel(start.point + f * (target.point - start.point), normal)
    return SphereModel(start.centre + f * (target.centre - start.centre),
                       start.radius + f * (target.radius - start.radius))


class ModelGlide:
    """The model to render at each tick: a new local model replaces the shown one over `duration_s`.

    The physics moves the local model in 150 Hz steps; rendered at once, each step is a force
    jump of K·(surface motion per frame). Gliding spreads it over the ticks of one physics period
    (at the cost of that much lag in the rendered surface). `duration_s` 0 renders each model at once.
    """

    def __init__(self, duration_s: float):
        self.duration_s = _check_non_negative(duration_s, "duration_s")
        self._target = self._shown = self._start = None
        self._since = 0.0

    def update(self, target: PlaneModel | SphereModel | None, now_s: float) -> PlaneModel | SphereModel | None:
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


def _rotation_matrix(rotation) -> np.ndarray:
    """A proper rotation matrix from a 3×3 matrix or an (x, y, z, w) quaternion, or ValueError."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape == (4,):
        r = quaternion_to_matrix(r)
    elif r.shape != (3, 3) or not np.isfinite(r).all():
        raise ValueError(f"FrameMap.rotation must be a finite 3x3 matrix or (x, y, z, w) quaternion, "
                         f"got shape {r.shape}")
    elif not (np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0.0):
        raise ValueError("FrameMap.rotation must be a proper rotation (orthonormal, det +1)")
    r = np.array(r)
    r.setflags(write=False)
    return r


@dataclass(frozen=True, eq=False)
class FrameMap:
    """Device workspace → liver frame: p_liver = scale·R·p_device + translation.

    `rotation` is a 3×3 matrix or a quaternion (x, y, z, w), `translation` is in
    metres, `scale` (> 0, dimensionless) multiplies device motion into liver motion.
    Forces are free vectors: they only rotate (by Rᵀ towards the device) and are
    not scaled, so a liver-side stiffness K (N/m) is felt at the device as K·scale
    N per metre of stylus motion — use that product in the passivity check.
    """

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "rotation", _rotation_matrix(self.rotation))
        object.__setattr__(self, "translation", _vector3(self.translation, "FrameMap.translation"))
        scale = float(self.scale)
        if not (np.isfinite(scale) and scale > 0.0):
            raise ValueError(f"FrameMap.scale must be finite and > 0, got {self.scale!r}")
        object.__setattr__(self, "scale", scale)

    def device_to_liver(self, point: np.ndarray) -> np.ndarray:
        """Device point (m) → liver point (m): scale·R·p + translation."""
        return self.scale * (self.rotation @ point) + self.translation

    def liver_to_device(self, point: np.ndarray) -> np.ndarray:
        """Liver point (m) → device point (m): Rᵀ·(p − translation)/scale."""
        return self.rotation.T @ (point - self.translation) / self.scale

    def liver_to_device_force(self, force: np.ndarray) -> np.ndarray:
        """Force (N) in the liver frame → device frame: Rᵀ·F (rotation only, no scale)."""
        return self.rotation.T @ force

    def device_to_liver_force(self, force: np.ndarray) -> np.ndarray:
        """Force (N) in the device frame → liver frame: R·F (rotation only, no scale)."""
        return self.rotation @ force


def _check_non_negative(value: float, name: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value >= 0.0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return value


def _check_period(period: float) -> float:
    period = float(period)
    if not (np.isfinite(period) and period > 0.0):
        raise ValueError(f"period must be finite and > 0 s, got {period!r}")
    return period


def passivity_damping_min(stiffness: float, period: float, virtual_damping: float = 0.0) -> float:
    """Smallest damping b (N·s/m) for a passive virtual wall: b > K·T/2 + |B| (Colgate & Schenkel 1997).

    K = `stiffness` (N/m) rendered at sample `period` T (s). In Colgate's result b is
    the damping physically present in the device and B the rendered (virtual) damping,
    which adds to the requirement; with B = 0 this is the K·T/2 bound.
    """
    return (_check_non_negative(stiffness, "stiffness") * _check_period(period) / 2.0
            + _check_non_negative(abs(virtual_damping), "virtual_damping"))


def max_passive_stiffness(damping: float, period: float, virtual_damping: float = 0.0) -> float:
    """Largest stiffness K (N/m) that damping b (N·s/m) keeps passive at `period` T (s): K < 2·(b − |B|)/T.

    The inverse of :func:`passivity_damping_min`; 0 when |B| ≥ b.
    """
    margin = (_check_non_negative(damping, "damping")
              - _check_non_negative(abs(virtual_damping), "virtual_damping"))
    return max(2.0 * margin / _check_period(period), 0.0)
