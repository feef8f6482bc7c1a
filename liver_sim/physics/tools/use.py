"""What a tool does besides pressing (paper P13, P14: docs/paper.md): grasp what it touches, or cut along each stroke.

A ToolUse is one tool's mode and what the mode remembers between frames; it decides, and the model acts
(liver_sim.physics.model.LiverModel.step_frame): before a frame, grasp what the tool touched at the last one or
let go (`before_frame`); during it, where the grasped nodes are held (`held_positions`); after it, the path of a
cutting stroke that just ended (`after_frame`), which the model cuts along.
"""
from __future__ import annotations

import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, candidate_nodes

TOOL_MODES = ("press", "grasp", "cut")
#: cut: a contact point joins the stroke's path when this far (m) from the last one.
CUT_PATH_STEP_M = 0.002


class ToolUse:
    """A tool's mode: press (Eq. 3 only), grasp or cut; `mode` may change between frames.

    grasp: at the first frame in contact the skin nodes within the tool (+ `grasp_margin_m`) are held where they
    are in the tool frame until the mode changes (`held_nodes`: this tool's; the model holds every tool's).  cut:
    the stroke's path is the local model's contact point, frame by frame (a point CUT_PATH_STEP_M from the last);
    when the tool leaves the surface the model is cut along it, `cut_depth_m` deep.
    """

    def __init__(self, mode: str = "press", grasp_margin_m: float = 0.005, cut_depth_m: float = 0.005):
        self.mode = mode
        self.grasp_margin_m = grasp_margin_m
        self.cut_depth_m = cut_depth_m
        self._in_contact = False
        self._path: list[np.ndarray] = []
        self.held_nodes = np.zeros(0, dtype=np.int64)
        self._grasp_offsets = np.zeros((0, 3))

    @property
    def mode(self) -> str:
        return self._mode

    @mode.setter
    def mode(self, mode: str) -> None:
        if mode not in TOOL_MODES:
            raise ValueError(f"parameter tool_mode must be one of {TOOL_MODES}, got {mode!r}")
        self._mode = mode

    @property
    def holding(self) -> bool:
        """Whether the tool holds nodes."""
        return self.held_nodes.size > 0

    def grasp(self, shape: ToolShape, pose: ToolPose, positions: np.ndarray, skin_nodes: np.ndarray) -> np.ndarray:
        """Hold the skin nodes (of `skin_nodes`) within the tool's bounding ball (+ `grasp_margin_m`) where they are
        now in the tool frame (`held_positions`); returns them (`held_nodes`)."""
        nodes = candidate_nodes(positions, skin_nodes, shape, pose, self.grasp_margin_m)
        self._grasp_offsets = (positions[nodes] - pose.position) @ pose.rotation
        self.held_nodes = nodes
        return nodes

    def release(self) -> None:
        """Hold nothing."""
        self.held_nodes = np.zeros(0, dtype=np.int64)

    def before_frame(self, pose: ToolPose | None) -> str | None:
        """'grasp' when in grasp mode the tool, at `pose`, touched the surface at the last frame and holds
        nothing; 'release' when it holds nodes in another mode; else None."""
        if self._mode == "grasp" and not self.holding and pose is not None and self._in_contact:
            return "grasp"
        if self._mode != "grasp" and self.holding:
            return "release"
        return None

    def held_positions(self, pose: ToolPose) -> np.ndarray:
        """Where the tool at `pose` holds the grasped nodes (m): their grasp offsets in the tool frame."""
        return pose.position + self._grasp_offsets @ pose.rotation.T

    def after_frame(self, local_model: LocalModel) -> np.ndarray | None:
        """Follow the stroke in cut mode: the path (P ≥ 2, 3) m of a stroke that ended with this frame (the tool
        left the surface, or the mode changed), to cut along; else None."""
        self._in_contact = local_model.in_contact
        if self._mode == "cut" and local_model.in_contact:
            if not self._path or np.linalg.norm(local_model.point - self._path[-1]) >= CUT_PATH_STEP_M:
                self._path.append(local_model.point.copy())
            return None
        path, self._path = self._path, []
        return np.array(path) if len(path) >= 2 else None
