"""One tool on the liver: what it is, where it was, what it touches and what it does (paper P9, P11; Eq. 3).

A Tool holds everything of one tool — its shape (physics.contact.tool_geometry.ToolShape), the local model it
publishes for the haptic loop and how far from the skin, the previous pose (the frame's motion runs from it), the
frame's contact arrays (physics.contact.kernels.ToolSweep), the stiffness it meets (physics.tools.local_stiffness) and
its use (physics.tools.use.ToolUse: press, grasp or cut): a second tool is a second Tool, with a `name` of
its own (the ROS namespace of its topics; '' for a tool in the root namespace).
"""
from __future__ import annotations

import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact.kernels import ToolSweep
from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, force_local_model, pull_local_model, tool_sweep
from liver_sim.physics.state import State
from liver_sim.physics.structure import Structure
from liver_sim.physics.tools.local_stiffness import REFRESH_FRAMES, LocalStiffness
from liver_sim.physics.tools.use import ToolUse

LOCAL_MODELS = ("plane", "sphere")


class Tool:
    """One tool: `shape`, `local_model_kind` ('plane' or 'sphere'), `local_model_reach_m` (a local model is
    published while the tool is this close to the skin, m), `use`, `stiffness_refresh_frames` (frames between two
    solves of the tissue's compliance under it: LocalStiffness), `name` (module docstring); `previous_pose` and
    `contact` (the ToolSweep of the last frame: its probes, candidates and contact rows)."""

    def __init__(self, shape: ToolShape | None = None, local_model: str = "plane", local_model_reach_m: float = 0.02,
                 use: ToolUse | None = None, stiffness_refresh_frames: int = REFRESH_FRAMES, name: str = ""):
        if local_model not in LOCAL_MODELS:
            raise ValueError(f"parameter local_model must be 'plane' or 'sphere', got {local_model!r}")
        self.name = name
        self.shape = shape or ToolShape()
        self.local_model_kind = local_model
        self.local_model_reach_m = float(local_model_reach_m)
        self.use = use or ToolUse()
        self.stiffness_refresh_frames = int(stiffness_refresh_frames)
        self.previous_pose: ToolPose | None = None
        self.contact: ToolSweep | None = None
        self._stiffness: tuple[Structure, LocalStiffness] | None = None

    def over_frame(self, structure: Structure, state: State, pose: ToolPose | None) -> ToolSweep:
        """The tool over the next frame (contact.tool_geometry.tool_sweep: its probes moving from the previous pose to
        `pose`,
        its candidate skin triangles; None: no tool), kept as `contact`; `pose` becomes the previous pose."""
        self.contact = tool_sweep(self.shape, pose, self.previous_pose, structure.params, self.local_model_reach_m,
                                  state.positions, structure.skin)
        self.previous_pose = pose
        return self.contact

    def stiffness_n_per_m(self, structure: Structure, state: State, others: Contacts | None = None) -> float:
        """K of the local model under the tool at the end of the frame (physics.tools.local_stiffness), the tissue's
        compliance solved on `structure`'s network (anew after a change), the other tools' pushing contact rows
        `others` holding it."""
        if self._stiffness is None or self._stiffness[0] is not structure:
            self._stiffness = (structure, LocalStiffness(structure.solver, structure.node_count,
                                                         self.stiffness_refresh_frames))
        params = structure.params
        return self._stiffness[1].stiffness_n_per_m(self.contact, state.positions, state.inv_mass,
                                                    params.contact_stiffness_n_per_m,
                                                    params.environment_damping_per_s, others)

    def local_model(self, structure: Structure, state: State, pose: ToolPose | None, force_on_tool_n: np.ndarray,
                    holding: bool, others: Contacts | None = None) -> LocalModel:
        """The local model for the haptic loop at the end of the frame: none without a tool; holding nodes, the
        plane of their pull (contact.tool_geometry.pull_local_model); else the one of the contact force
        (contact.tool_geometry.force_local_model), its stiffness with the other tools' pushing rows
        `others` in place."""
        if pose is None:
            return LocalModel.invalid()
        if holding:
            return pull_local_model(pose, force_on_tool_n, structure.params.contact_stiffness_n_per_m,
                                    self.shape.radius_m)
        return force_local_model(self.shape, pose, self.contact, force_on_tool_n,
                                 self.stiffness_n_per_m(structure, state, others), self.local_model_reach_m,
                                 self.local_model_kind, state.positions)

    def forget(self) -> None:
        """No previous pose (the next frame's tool starts at rest), nothing held and no tissue compliance known."""
        self.previous_pose = None
        self.use.release()
        if self._stiffness is not None:
            self._stiffness[1].reset()
