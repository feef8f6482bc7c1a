"""Tool scripts played offline on the model, and what they record (behaviours B1–B3 of docs/paper.md).

`press_release` lowers a sphere tool onto the top of the liver, presses, holds, withdraws and
waits (the `press_release` script of liver_sim.tool.scripts), recording the force, the tool and
the shape at every frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.tool.scripts import ScriptSettings, make_script


def offline_press_release(mesh: TetMesh, tool_radius_m: float, rest_s: float = 3.0) -> ScriptSettings:
    """The offline press-and-release: 2 cm into the top of `mesh`, held, withdrawn quickly, then rest."""
    return ScriptSettings(anchor_m=tuple(press_anchor(mesh)), tool_radius_m=tool_radius_m, depth_m=0.02,
                          clearance_m=0.01, approach_s=0.3, press_s=1.0, hold_s=0.5, withdraw_s=0.05, rest_s=rest_s)


@dataclass
class Trace:
    """Per-frame record of a scripted run: times (s), tool tip (m), force on the tool (N), displacements (m)."""

    time_s: list = field(default_factory=list)
    tool_position_m: list = field(default_factory=list)
    tool_force_n: list = field(default_factory=list)
    max_displacement_m: list = field(default_factory=list)
    max_deformation_m: list = field(default_factory=list)
    in_contact: list = field(default_factory=list)
    peak_positions_m: np.ndarray | None = None
    divergences: list = field(default_factory=list)

    def arrays(self) -> dict:
        """The per-frame lists as numpy arrays."""
        return {name: np.asarray(getattr(self, name)) for name in
                ("time_s", "tool_position_m", "tool_force_n", "max_displacement_m", "max_deformation_m",
                 "in_contact")}


def press_release(model: LiverModel, settings: ScriptSettings | None = None, progress=None) -> Trace:
    """Play the `press_release` tool script (default: offline_press_release) on `model`; returns the trace.

    The tool tip starts `clearance_m` above the top of the liver (tool surface to skin), goes down
    to `depth_m` below the rest surface, holds, withdraws and the model is left to recover.
    """
    script = make_script("press_release",
                         settings or offline_press_release(model.structure.mesh, model.tool.shape.radius_m))
    frames = int(round(script.duration_s * model.structure.params.frame_rate_hz))
    trace = Trace()
    peak_force = -1.0
    for frame in range(frames):
        t = (frame + 1) * model.structure.frame_period_s
        tip = script.position_at(t)
        result = model.step_frame(ToolPose(tip))
        trace.time_s.append(t)
        trace.tool_position_m.append(tip)
        trace.tool_force_n.append(result.tool_force_n)
        trace.max_displacement_m.append(float(model.state.displacement_m(model.structure).max()))
        trace.max_deformation_m.append(float(deformation_m(model.structure.mesh.points, model.state.positions).max()))
        trace.in_contact.append(result.local_model.in_contact)
        if result.divergence:
            trace.divergences.append(result.divergence)
        magnitude = float(np.linalg.norm(result.tool_force_n))
        if magnitude > peak_force:
            peak_force = magnitude
            trace.peak_positions_m = model.state.positions.copy()
        if progress and frame % int(model.structure.params.frame_rate_hz) == 0:
            progress(t, script.duration_s)
    return trace


def rigid_fit(rest: np.ndarray, current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation R (3×3) and translation t of the rigid motion nearest `current` (Kabsch, least squares):
    current ≈ rest·Rᵀ + t."""
    rest_centre, current_centre = rest.mean(axis=0), current.mean(axis=0)
    u, _, vt = np.linalg.svd((current - current_centre).T @ (rest - rest_centre))
    rotation = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    return rotation, current_centre - rest_centre @ rotation.T


def rigid_rotation_deg(rest: np.ndarray, current: np.ndarray) -> float:
    """Angle (degrees) of the rotation of the rigid motion nearest `current` (rigid_fit): how far the organ
    turned as a whole."""
    rotation, _ = rigid_fit(rest, current)
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))))


def deformation_m(rest: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Per-node distance (m) between the rest shape and the current one with its best rigid motion
    removed (rigid_fit): the change of shape, without the organ turning on its supports."""
    rotation, shift = rigid_fit(rest, current)
    return np.linalg.norm((current - shift) @ rotation - rest, axis=1)


def recovery_time_s(trace: Trace, fraction: float = 0.1, measure: str = "max_deformation_m") -> float:
    """Time from the tool's last contact until `measure` (the largest change of shape, by default)
    falls below `fraction` of its value then (inf if it never does within the trace)."""
    data = trace.arrays()
    release_time_s = data["time_s"][np.flatnonzero(data["in_contact"])[-1]]
    after = data["time_s"] >= release_time_s
    start = data[measure][after][0]
    below = np.flatnonzero(data[measure][after] < fraction * start)
    return float(data["time_s"][after][below[0]] - release_time_s) if below.size else float("inf")
