"""Plausibility of the bridge's inputs (no ROS): every number that reaches the tick is finite and physically
possible, or the sample is refused with the reason (the node counts it and keeps the previous good one).

Finiteness and well-formed quaternions are the message conversions' part (msg_defs.finite); here:
the workspace bound around the liver (a tip, a plane point or a sphere centre farther than `radius_m` from
`centre` is implausible, and so an infinite plane pushes no tool 50 m away) and the size of a force.
"""
from __future__ import annotations

import math

import numpy as np

from liver_sim.base.checks import positive, vector3
from liver_sim.base.local_model import LocalModel

#: A physics contact force above this (N) is not a contact force: refused, not clamped.
IMPLAUSIBLE_FORCE_N = 100.0


class InputCheck:
    """Workspace sphere of `radius_m` (m) about `centre` (m, liver frame); each method returns None for a
    plausible input, else why it is refused."""

    def __init__(self, centre, radius_m: float):
        self.centre = vector3(centre, "workspace_centre_m")
        self.radius_m = positive(radius_m, "workspace_radius_m")

    def _outside(self, what: str, point: np.ndarray) -> str | None:
        distance = math.dist(point, self.centre)
        if distance <= self.radius_m:
            return None
        return (f"{what} {np.round(point, 4).tolist()} m is {distance:.3g} m from the workspace centre, beyond "
                f"workspace_radius_m={self.radius_m:g}")

    def tip(self, position: np.ndarray) -> str | None:
        """The tool tip (m): finite and within the workspace."""
        if not np.isfinite(position).all():
            return f"tool tip {position.tolist()} is not finite"
        return self._outside("tool tip", position)

    def model(self, model: LocalModel | None) -> str | None:
        """A local model (None: no surface): its plane point, or its sphere's centre and radius, in the workspace."""
        if model is None or not model.valid:
            return None
        if model.kind == "plane":
            return self._outside("plane point", model.point)
        if model.radius_m > self.radius_m:
            return f"sphere radius {model.radius_m:g} m exceeds workspace_radius_m={self.radius_m:g}"
        return self._outside("sphere centre", model.centre)

    @staticmethod
    def force(force: np.ndarray) -> str | None:
        """A physics contact force (N): finite and at most IMPLAUSIBLE_FORCE_N."""
        if not np.isfinite(force).all():
            return f"force {force.tolist()} N is not finite"
        magnitude = math.hypot(*force)
        if magnitude > IMPLAUSIBLE_FORCE_N:
            return f"force of {magnitude:.3g} N is implausible (above {IMPLAUSIBLE_FORCE_N:g} N)"
        return None
