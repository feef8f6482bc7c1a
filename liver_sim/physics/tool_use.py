"""What the tool does besides pressing (paper P13, P14: docs/paper.md): grasp what it touches, or cut along each stroke.

`ToolUse.step_frame` runs one LiverModel frame with the tool in its mode: grasp or let go before it,
hold the grasped nodes during it, follow a cutting stroke after it and cut when the tool leaves the
surface.  The frame pipeline (physics node and offline re-simulation) steps the model through it.
"""
from __future__ import annotations

import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact import ToolPose, candidate_nodes
from liver_sim.physics.model import FrameResult, LiverModel

TOOL_MODES = ("press", "grasp", "cut")
#: cut: a contact point joins the stroke's path when this far (m) from the last one.
CUT_PATH_STEP_M = 0.002


class ToolUse:
    """The tool's mode on a model: press (Eq. 3 only), grasp or cut; `mode` may change between frames.

    grasp: at the first frame in contact the skin nodes within the tool (+ `grasp_margin_m`) are held
    (`grasp`) until the mode changes.  cut: the stroke's path is the local model's contact point,
    frame by frame; when the tool leaves the surface the model is cut along it, `cut_depth_m` deep
    (LiverModel.cut).  `events` collects what happened, for a log; `failures` why a cut or a tear failed
    (whatever it raised: the model is then as it was and the frame goes on), for a log and a count.
    """

    def __init__(self, model: LiverModel, mode: str = "press", grasp_margin_m: float = 0.005,
                 cut_depth_m: float = 0.005):
        self.model = model
        self.mode = mode
        self.grasp_margin_m = grasp_margin_m
        self.cut_depth_m = cut_depth_m
        self.events: list[str] = []
        self.failures: list[str] = []
        self._in_contact = False
        self._path: list[np.ndarray] = []
        self._grasp_offsets = np.zeros((0, 3))

    @property
    def mode(self) -> str:
        return self._mode

    @mode.setter
    def mode(self, mode: str) -> None:
        if mode not in TOOL_MODES:
            raise ValueError(f"parameter tool_mode must be one of {TOOL_MODES}, got {mode!r}")
        self._mode = mode

    def grasp(self, pose: ToolPose) -> int:
        """Hold the skin nodes within the tool's bounding ball (+ `grasp_margin_m`) where they are in the
        tool frame: from the next frame on they move with the tool, kinematically, until `release()`.
        Returns how many nodes are held."""
        model = self.model
        nodes = candidate_nodes(model.positions, model.mesh.skin_nodes, model.tool, pose, self.grasp_margin_m)
        self._grasp_offsets = (model.positions[nodes] - pose.position) @ pose.rotation
        model.hold(nodes)
        return len(nodes)

    def release(self) -> None:
        """Let go of the grasped nodes."""
        self.model.hold(np.zeros(0, dtype=np.int64))

    def step_frame(self, pose: ToolPose | None) -> tuple[FrameResult, bool]:
        """One model frame with the tool at `pose` in its mode: (the model's result, True when a cut
        changed the mesh after it)."""
        self.before_frame(pose)
        held = None
        if pose is not None and self.model.held_nodes.size:  # where the tool at `pose` holds them
            held = pose.position + self._grasp_offsets @ pose.rotation.T
        result = self.model.step_frame(pose, held)
        if result.topology_failure:
            self.failures.append(result.topology_failure)
        return result, self.after_frame(result.local_model)

    def before_frame(self, pose: ToolPose | None) -> None:
        """Grasp what the tool touches in grasp mode; let go in any other mode."""
        grasping = self.model.held_nodes.size > 0
        if self._mode == "grasp" and not grasping and pose is not None and self._in_contact:
            self.events.append(f"grasped {self.grasp(pose)} skin node(s)")
        elif self._mode != "grasp" and grasping:
            self.release()
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
        except Exception as exc:  # e.g. a path along which no blade direction can be found
            self.failures.append(f"cut along {len(path)} points failed, the mesh is unchanged: "
                                 f"{type(exc).__name__}: {exc}")
            return False
