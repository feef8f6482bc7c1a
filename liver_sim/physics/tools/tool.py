"""One tool on the liver: what it is, where it was, what it touches and what it does (paper P9, P11; Eq. 3).

A Tool is what one tool is — its shape (physics.contact.tool_geometry.ToolShape), the local model it publishes for
the haptic loop and how far from the skin, how often the stiffness it meets is solved (physics.tools.local_stiffness)
and its use (physics.tools.use.ToolUse: press, grasp or cut): a second tool is a second Tool, with a `name` of
its own (the ROS namespace of its topics; '' for a tool in the root namespace).  Where it was, what it touched and
what it holds change from frame to frame: they are its physics.state.ToolState.
"""
from __future__ import annotations

import numpy as np

from liver_sim.base.local_model import LocalModel
from liver_sim.physics.contact.kernels import ToolSweep
from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, force_local_model, pull_local_model, tool_sweep
from liver_sim.physics.state import State, ToolState
from liver_sim.physics.structure import Structure
from liver_sim.physics.tools.local_stiffness import REFRESH_FRAMES, stiffness_n_per_m
from liver_sim.physics.tools.use import ToolUse

LOCAL_MODELS = ("plane", "sphere")


class Tool:
    """One tool: `shape`, `local_model_kind` ('plane' or 'sphere'), `local_model_reach_m` (a local model is
    published while the tool is this close to the skin, m), `use`, `stiffness_refresh_frames` (frames between two
    solves of the tissue's compliance under it: physics.tools.local_stiffness), `name` (module docstring).  What
    its frames change is its ToolState in the liver's State."""

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

    def sweep(self, structure: Structure, positions: np.ndarray, tool: ToolState, pose: ToolPose | None) -> ToolSweep:
        """The tool over the next frame (contact.tool_geometry.tool_sweep: its probes moving from the previous pose
        to `pose`, its candidate skin triangles near `positions`; None: no tool), kept as the tool state's `sweep`;
        `pose` becomes its previous pose."""
        tool.sweep = tool_sweep(self.shape, pose, tool.previous_pose, structure.params, self.local_model_reach_m,
                                positions, structure.skin)
        tool.previous_pose = pose
        return tool.sweep

    def local_model(self, structure: Structure, state: State, tool: ToolState, pose: ToolPose | None,
                    force_on_tool_n: np.ndarray, holding: bool, others: Contacts | None = None) -> LocalModel:
        """The local model for the haptic loop at the end of the frame: none without a tool; holding nodes, the
        plane of their pull (contact.tool_geometry.pull_local_model); else the one of the contact force
        (contact.tool_geometry.force_local_model), its stiffness (physics.tools.local_stiffness) with the other
        tools' pushing rows `others` in place."""
        if pose is None:
            return LocalModel.invalid()
        params = structure.params
        if holding:
            return pull_local_model(pose, force_on_tool_n, params.contact_stiffness_n_per_m, self.shape.radius_m)
        stiffness = stiffness_n_per_m(structure.solver, tool, state.positions, state.inv_mass,
                                      params.contact_stiffness_n_per_m, params.environment_damping_per_s, others,
                                      state.history.rotations, self.stiffness_refresh_frames)
        return force_local_model(self.shape, pose, tool.sweep, force_on_tool_n, stiffness, self.local_model_reach_m,
                                 self.local_model_kind, state.positions)
