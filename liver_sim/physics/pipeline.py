"""The physics frame pipeline, without ROS: from the tool poses received to one frame's outputs.

`FramePipeline` is what the physics node and offline re-simulation both run.  A received pose (of one of the
model's tools) is gated (outside the liver's bounds + `workspace_margin_m` it is refused and counted); a frame
takes each tool's newest pose unless it is older than `tool_pose_timeout_s` (then: that tool is away), steps the
model (LiverModel.step_frame, the tools' use included: grasp, hold, cut), and says whether the surface must be
republished (a tear or a cut) and whether the skin marker is due (`marker_rate_hz`), with the
events worth a log line.  The adapters add only their I/O and clock: ROS messages, parameters and
publishers (liver_sim.nodes.physics_node), bag I/O and deterministic offline timing
(liver_sim.sessions.resimulate).

The node's parameter table and the model it names are in liver_sim.physics.parameters.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import FrameResult, LiverModel
from liver_sim.physics.parameters import PhysicsParameters


@dataclass(frozen=True)
class Event:
    """Something worth a log line.  kind: 'refused' (a tool pose), 'diverged' (the model was reset),
    'topology' (a tear or a cut changed the mesh), 'topology_failed' (a tear or a cut failed, the model
    is as it was) or 'tool' (ToolUse's events)."""

    kind: str
    text: str


@dataclass(frozen=True)
class Frame:
    """One frame's outputs: the model's result; `surface_changed`: a tear or a cut changed the mesh, so
    its surface must be republished (before the nodes that index it); `marker_due`: the skin marker is
    published this frame; `events` since the last frame, in order."""

    result: FrameResult
    surface_changed: bool
    marker_due: bool
    events: tuple[Event, ...]


class FramePipeline:
    """The frame sequence of one model, configured by the physics node's parameters (PhysicsParameters).

    `receive`/`refuse` take each tool pose message of tool `tool` (its index in `model.tools`; time in the clock
    `step` is called with), `step` runs a frame.  A tool's `use.mode` may change between frames.  Counts: `frames`,
    `refused_poses` (every tool's), `topology_failures` (tears and cuts that failed and left the model as it was).
    """

    def __init__(self, model: LiverModel, parameters: PhysicsParameters):
        self.model = model
        lower, upper = model.structure.mesh.bounds
        self.workspace = (lower - parameters.workspace_margin_m, upper + parameters.workspace_margin_m)
        self.pose_timeout_s = parameters.tool_pose_timeout_s
        self.marker_every = max(1, round(parameters.rate_hz / parameters.marker_rate_hz))
        self.frames = 0
        self.refused_poses = 0
        self.topology_failures = 0
        tools = len(model.tools)
        self._poses: list[ToolPose | None] = [None] * tools
        self._pose_times_s = [-np.inf] * tools
        self._events: list[Event] = []

    def receive(self, position: np.ndarray, orientation_xyzw, time_s: float, tool: int = 0) -> ToolPose | None:
        """Take tool `tool`'s pose received at `time_s`: its newest pose from then on; None when refused
        (outside the workspace)."""
        if np.any(position < self.workspace[0]) or np.any(position > self.workspace[1]):
            self.refuse(f"tool position {np.round(position, 3).tolist()} m is outside the workspace", time_s, tool)
            return None
        self._poses[tool], self._pose_times_s[tool] = ToolPose(position, tuple(orientation_xyzw)), time_s
        return self._poses[tool]

    def refuse(self, reason: str, time_s: float, tool: int = 0) -> None:
        """Count a pose of tool `tool` refused for `reason` (e.g. malformed); it stands for that tool away from
        `time_s` on."""
        self.refused_poses += 1
        self._poses[tool], self._pose_times_s[tool] = None, time_s
        name = self.model.tools[tool].name
        self._events.append(Event("refused", f"ignored {name + ' ' if name else ''}tool pose: {reason}"))

    def step(self, now_s: float) -> Frame:
        """One frame at `now_s` with each tool's newest pose unless older than tool_pose_timeout_s (then that tool
        is away)."""
        poses = [pose if now_s - time_s <= self.pose_timeout_s else None
                 for pose, time_s in zip(self._poses, self._pose_times_s)]
        result = self.model.step_frame(*poses)
        events, self._events = self._events, []
        if result.divergence:
            events.append(Event("diverged", result.divergence))
        events += [Event("topology", self._topology_text(cause)) for cause in result.topology_changes]
        events += [Event("tool", text) for text in result.tool_events]
        events += [Event("topology_failed", text) for text in result.topology_failures]
        self.topology_failures += len(result.topology_failures)
        marker_due = self.frames % self.marker_every == 0
        self.frames += 1
        return Frame(result, result.topology_changed, marker_due, tuple(events))

    def _topology_text(self, cause: str) -> str:
        structure = self.model.structure
        mesh = structure.mesh
        stability = "implicit" if structure.implicit else f"stable below {structure.stable_dt_s * 1e6:.0f} us"
        return (f"{cause}: {len(mesh.points)} nodes, {len(mesh.tets)} tets, {len(mesh.skin)} skin triangles; "
                f"{structure.params.substeps} substeps per frame ({stability})")
