"""The local model of the touched surface (paper §2.5; P10–P11 of docs/paper.md): a plane or a sphere near the tool.

The physics (150 Hz) fits it at the end of each frame; the wire carries it as a Marker; between
physics updates the haptic loop renders it analytically. Everything here works on 3-vectors in
metres, without ROS.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from liver_sim.base.checks import positive, vector3

KINDS = ("plane", "sphere")
#: A tip closer than this (m) to a sphere model's centre gets the fallback direction +z.
CENTRE_EPS_M = 1e-12
_UP = np.array([0.0, 0.0, 1.0])
_UP.setflags(write=False)
_ZERO = np.zeros(3)
_ZERO.setflags(write=False)


@dataclass(frozen=True, eq=False)
class LocalModel:
    """The local model of §2.5 (P11), immutable.

    kind 'plane': the surface through `point` (m) with outward unit `normal`, the liver on the −normal
    side; kind 'sphere': a sphere of `radius_m` (m) about `centre` (m) holding the liver (`point` and
    `normal` then keep the plane the physics fitted beside it). `valid` is False when no surface is
    within reach of the tool. `depth_m` is the tool's penetration of the model at the physics' pose (m),
    `in_contact` whether the physics had a contact force. `stiffness_n_per_m`: the K (N/m) to render it
    with, the tissue's local stiffness under the tool (None: the renderer's own).

    Refuses (ValueError naming the field) an unknown kind, non-finite or misshapen vectors, a zero
    normal, a valid sphere without a finite radius > 0, and a K that is not a finite number > 0. The normal is
    normalised.
    """

    kind: str
    valid: bool
    point: np.ndarray
    normal: np.ndarray
    centre: np.ndarray
    radius_m: float
    depth_m: float
    in_contact: bool
    stiffness_n_per_m: float | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"LocalModel.kind must be 'plane' or 'sphere', got {self.kind!r}")
        for name in ("point", "centre") if self.kind == "plane" else ("centre", "point"):  # its surface's first
            object.__setattr__(self, name, vector3(getattr(self, name), f"LocalModel.{name}"))
        normal = vector3(self.normal, "LocalModel.normal")
        length = float(np.linalg.norm(normal))
        if not length > 0.0:
            raise ValueError(f"LocalModel.normal must be non-zero, got {self.normal!r}")
        normal = normal / length
        normal.setflags(write=False)
        object.__setattr__(self, "normal", normal)
        if self.valid and self.kind == "sphere":
            object.__setattr__(self, "radius_m", positive(self.radius_m, "LocalModel.radius_m"))
        if self.stiffness_n_per_m is not None:
            object.__setattr__(self, "stiffness_n_per_m", positive(self.stiffness_n_per_m,
                                                                   "LocalModel.stiffness_n_per_m"))

    @classmethod
    def derived(cls, model: LocalModel, **fields) -> LocalModel:
        """`model` with `fields` replaced, without the checks: only for values computed from checked models (a
        blend of two, at every 1 kHz tick), which are finite already; a new normal must be a unit (3,) array."""
        derived = object.__new__(cls)
        values = derived.__dict__
        values.update(model.__dict__)
        values.update(fields)
        return derived

    @classmethod
    def invalid(cls) -> LocalModel:
        """No surface near the tool."""
        return cls("plane", False, _ZERO, _UP, _ZERO, 0.0, 0.0, False)

    @classmethod
    def plane(cls, point, normal, stiffness_n_per_m: float | None = None) -> LocalModel:
        """A valid plane model of the surface alone (what a Marker carries): no depth seen, not in contact."""
        return cls("plane", True, point, normal, point, 0.0, 0.0, False, stiffness_n_per_m)

    @classmethod
    def sphere(cls, centre, radius_m: float, stiffness_n_per_m: float | None = None) -> LocalModel:
        """A valid sphere model of the surface alone (what a Marker carries): no plane beside it (point =
        centre, normal +z), no depth seen, not in contact."""
        return cls("sphere", True, centre, _UP, centre, radius_m, 0.0, False, stiffness_n_per_m)


def penetration(model: LocalModel, tip: np.ndarray, tool_radius: float = 0.0) -> tuple[float, np.ndarray]:
    """Depth (m, ≥ 0) of the tool sphere (centre `tip`, radius `tool_radius` m) into `model`,
    and the unit direction in which the surface pushes the tool.

    The paper minimises the tip–surface distance with Lagrange multipliers (§2.5);
    for a plane and a sphere that minimisation has these closed forms:

    - plane:  depth = max(0, r_tool − (tip − point)·n),            direction = n;
    - sphere: depth = max(0, R + r_tool − |tip − centre|),         direction = (tip − centre)/|tip − centre|
      (+z when the tip is within CENTRE_EPS_M of the centre, where every direction is equally short).

    An invalid model (no surface) gives depth 0 and a zero direction. A non-finite `tip` gives a
    non-finite result; the safety stage turns that into zero force.
    """
    if not model.valid:
        return 0.0, _ZERO
    if model.kind == "plane":
        depth = tool_radius - float(np.dot(tip - model.point, model.normal))
        return max(depth, 0.0), model.normal
    offset = tip - model.centre
    distance = float(np.linalg.norm(offset))
    direction = offset / distance if distance > CENTRE_EPS_M else _UP
    return max(model.radius_m + tool_radius - distance, 0.0), direction
