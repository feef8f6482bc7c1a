"""What a tool does besides pressing (paper P13, P14: docs/paper.md): grasp what it touches, or cut along each stroke.

A ToolUse is one tool's mode; what the mode remembers between frames is the tool's state (physics.state.ToolState).
It decides, and the frame acts (liver_sim.physics.frame): before a frame, grasp what the tool touched at the last one or
let go (`before_frame`); during it, where the grasped nodes are held (`held_positions`); after it, the path of a
cutting stroke that just ended (`after_frame`), which the model cuts along.
"""
from __future__ import annotations

import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, candidate_nodes
from liver_sim.physics.state import ToolState

TOOL_MODES = ("press", "grasp", "cut")
#: cut: a contact point joins the stroke's path when this far (m) from the last one.
CUT_PATH_STEP_M = 0.002


class ToolUse:
    """A tool's mode: press (Eq. 3 only), grasp or cut; `mode` may change between frames.  What the mode remembers
    between frames is the tool's state (physics.state.ToolState), which each method takes.

    grasp: at the first frame in contact the skin nodes within the tool (+ `grasp_margin_m`) are held where they
    are in the tool frame until the mode changes (ToolState.held_nodes: this tool's; the state holds every tool's).
    cut: the stroke's path is the local model's contact point, frame by frame (a point CUT_PATH_STEP_M from the
    last); when the tool leaves the surface the model is cut along it, `cut_depth_m` deep.
    """

    def __init__(self, mode: str = "press", grasp_margin_m: float = 0.005, cut_depth_m: float = 0.005):
        self.mode = mode
        self.grasp_margin_m = grasp_margin_m
        self.cut_depth_m = cut_depth_m

    @property
    def mode(self) -> str:
        return self._mode

    @mode.setter
    def mode(self, mode: str) -> None:
        if mode not in TOOL_MODES:
            raise ValueError(f"parameter tool_mode must be one of {TOOL_MODES}, got {mode!r}")
        self._mode = mode

    def grasp(self, state: ToolState, shape: ToolShape, pose: ToolPose, positions: np.ndarray,
              skin_nodes: np.ndarray) -> np.ndarray:
        """Hold the skin nodes (of `skin_nodes`) within the tool's bounding ball (+ `grasp_margin_m`) where they are
        now in the tool frame (`held_positions`); returns them (the tool state's held_nodes)."""
        nodes = candidate_nodes(positions, skin_nodes, shape, pose, self.grasp_margin_m)
        state.grasp_offsets = (positions[nodes] - pose.position) @ pose.rotation
        state.held_nodes = nodes
        return nodes

    def before_frame(self, state: ToolState, pose: ToolPose | None) -> str | None:
        """'grasp' when in grasp mode the tool, at `pose`, touched the surface at the last frame and holds
        nothing; 'release' when it holds nodes in another mode; else None."""
        if self._mode == "grasp" and not state.holding and pose is not None and state.in_contact:
            return "grasp"
        if self._mode != "grasp" and state.holding:
            return "release"
        return None

    def after_frame(self, state: ToolState, local_model: LocalModel) -> np.ndarray | None:
        """Follow the stroke in cut mode: the path (P ≥ 2, 3) m of a stroke that ended with this frame (the tool
        left the surface, or the mode changed), to cut along; else None."""
        state.in_contact = local_model.in_contact
        if self._mode == "cut" and local_model.in_contact:
            if not state.cut_path or np.linalg.norm(local_model.point - state.cut_path[-1]) >= CUT_PATH_STEP_M:
                state.cut_path.append(local_model.point.copy())
            return None
        path, state.cut_path = state.cut_path, []
        return np.array(path) if len(path) >= 2 else None


def held_positions(state: ToolState, pose: ToolPose) -> np.ndarray:
    """Where the tool at `pose` holds its grasped nodes (m): their grasp offsets in the tool frame."""
    return pose.position + state.grasp_offsets @ pose.rotation.T


def release(state: ToolState) -> None:
    """Hold nothing."""
    state.held_nodes = np.zeros(0, dtype=np.int64)
