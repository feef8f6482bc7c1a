"""What the tool does besides pressing (P13, P14): grasp what it touches, or cut along each stroke.

`ToolUse` wraps one LiverModel frame: `before_frame` grasps or lets go, `after_frame` follows a cutting
stroke and cuts when the tool leaves the surface.  The physics node and offline re-simulation use it alike.
"""
from __future__ import annotations

import numpy as np

from liver_sim.physics.contact import LocalModel, ToolPose
from liver_sim.physics.model import LiverModel

TOOL_MODES = ("press", "grasp", "cut")
#: cut: a contact point joins the stroke's path when this far (m) from the last one.
CUT_PATH_STEP_M = 0.002


class ToolUse:
    """The tool's mode on a model: press (Eq. 3 only), grasp or cut; `mode` may change between frames.

    grasp: at the first frame in contact the skin nodes within the tool (+ `grasp_margin_m`) are held
    (LiverModel.grasp) until the mode changes.  cut: the stroke's path is the local model's contact
    point, frame by frame; when the tool leaves the surface the model is cut along it, `cut_depth_m`
    deep (LiverModel.cut).  `events` collects what happened, for a log.
    """

    def __init__(self, model: LiverModel, mode: str = "press", grasp_margin_m: float = 0.005,
                 cut_depth_m: float = 0.005):
        self.model = model
        self.mode = mode
        self.grasp_margin_m = grasp_margin_m
        self.cut_depth_m = cut_depth_m
        self.events: list[str] = []
        self._in_contact = False
        self._path: list[np.ndarray] = []

    @property
    def mode(self) -> str:
        return self._mode

    @mode.setter
    def mode(self, mode: str) -> None:
        if mode not in TOOL_MODES:
            raise ValueError(f"parameter tool_mode must be one of {TOOL_MODES}, got {mode!r}")
        self._mode = mode

    def before_frame(self, pose: ToolPose | None) -> None:
        """Grasp what the tool touches in grasp mode; let go in any other mode."""
        grasping = self.model.grasped_nodes.size > 0
        if self._mode == "grasp" and not grasping and pose is not None and self._in_contact:
            self.events.append(f"grasped {self.model.grasp(pose, self.grasp_margin_m)} skin node(s)")
        elif self._mode != "grasp" and grasping:
            self.model.release()
            self.events.append("released the grasped nodes")

    def after_frame(self, local_model: LocalModel) -> bool:
        """Follow the stroke in cut mode and cut when the tool leaves the surface; True when the mesh changed."""
        self._in_contact = local_model.in_contact
        if self._mode == "cut" and local_model.in_contact:
            if not self._path or np.linalg.norm(local_model.point - self._path[-1]) >= CUT_PATH_STEP_M:
                self._path.append(local_model.point.copy())
            return False
        path, self._path = self._path, []
        if len(path) < 2:
            return False
        try:
            return self.model.cut(np.array(path), self.cut_depth_m)
        except ValueError as exc:  # e.g. a path along which no blade direction can be found
            self.events.append(f"cut along {len(path)} points refused: {exc}")
            return False
