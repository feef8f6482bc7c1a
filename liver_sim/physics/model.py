"""The heterogeneous mass-spring liver (paper §2): a Structure, its State and its tools, stepped frame by frame.

`LiverModel.step_frame(*poses)` advances one frame with each tool at its pose (physics.frame.step, the frame's
stages); tears and cuts replace the structure and state whole (physics.frame.change_topology), and a divergence
resets the state to rest (physics.state.rest_state).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from liver_sim.base import kernel_cache
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics import frame
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.frame import FrameResult, apply_change
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.state import rest_state
from liver_sim.physics.structure import initial_structure
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.topology.change import TopologyChange

__all__ = ["FrameResult", "LiverModel"]


class LiverModel:
    """A liver: its `structure` (replaced whole by a tear or a cut), its `state` (everything a frame changes, each
    tool's included) and its `tools` (Tools, one by default; `tool` is the first); `divergences` counts the frames
    that diverged (the state was then reset to rest).  More than one tool needs the implicit integrator (the
    explicit kernels step one tool's contact).

    `state.external_forces_n` (N, 3) are applied to the nodes at every step (zero by default).
    `state.held_nodes` (every tool's, see `grasp`) are moved by the tools, like the fixed nodes by the scene, not
    integrated.  With `params.support` 'organ' and `fixed_nodes` None, no node is fixed unless the support regions
    hold no capsule node of the mesh (then the paper's central tet is, as with 'paper'):
    structure.initial_structure.
    """

    def __init__(self, mesh: TetMesh, params: ModelParams | None = None, tool: Tool | Sequence[Tool] | None = None):
        self.structure = initial_structure(mesh, params)
        self.tools = (tool,) if isinstance(tool, Tool) else tuple(tool) if tool is not None else (Tool(),)
        names = [t.name for t in self.tools]
        if not self.tools or len(set(names)) != len(names):
            raise ValueError(f"parameter tools must name one tool or more, each once, got {names}")
        if len(self.tools) > 1 and not self.structure.implicit:
            raise ValueError(f"parameter integrator={self.structure.params.integrator!r}: {len(self.tools)} tools "
                             "need implicit_euler (an explicit integrator steps one tool's contact)")
        self.state = rest_state(self.structure, len(self.tools))
        self.divergences = 0

    @property
    def tool(self) -> Tool:
        """The first tool (the only one by default)."""
        return self.tools[0]

    def step_frame(self, *poses: ToolPose | None) -> FrameResult:
        """Advance one frame with each tool at its pose, in the order of `tools` (None: that tool is away; no pose
        at all: every tool is); resets to rest on divergence (physics.frame).

        Holding nodes (grasp), a tool moves them to where it holds them, at the speed that takes them there in
        one frame, instead of pushing: its force is the tissue's pull on them and its local model
        contact.tool_geometry.pull_local_model's.  With `params.tearing`, faces stretched beyond their threshold
        then open."""
        self.structure, self.state, result = frame.step(self.structure, self.state, self.tools, self._poses(poses))
        self.divergences += result.divergence is not None
        return result

    def _poses(self, poses: tuple) -> tuple:
        """One pose (or None) per tool: `poses` as given, or every tool away when none is given."""
        if not poses:
            return (None,) * len(self.tools)
        if len(poses) != len(self.tools):
            raise ValueError(f"step_frame takes one pose per tool: {len(self.tools)}, got {len(poses)}")
        return poses

    def before_frame(self, *poses: ToolPose | None) -> tuple[str, ...]:
        """Each tool's use before a frame (physics.frame.use_before): grasp what it touches, or let go; what they
        did."""
        return frame.use_before(self.structure, self.state, self.tools, self._poses(poses))

    def after_frame(self, *local_models) -> tuple[list[str], list[str]]:
        """Each tool's use after a frame with its local model (in the order of `tools`): a cutting stroke that ended
        is cut along (physics.frame.cut_stage); (['cut', …] or [], why each failed or [])."""
        changes, failures = [], []
        self.structure, self.state = frame.cut_stage(self.structure, self.state, self.tools, local_models, changes,
                                                     failures)
        return changes, failures

    def grasp(self, pose: ToolPose, tool: int = 0) -> int:
        """Let tool `tool` hold the skin nodes it touches at `pose` (none another tool holds), from the next frame on
        moved with it, kinematically, until `release()`; returns how many."""
        return frame.grasp(self.structure, self.state, self.tools, tool, pose)

    def release(self, tool: int | None = None) -> None:
        """Let go of the nodes tool `tool` holds (None: every tool's)."""
        frame.let_go(self.structure, self.state, tool)

    def cut(self, path_m: np.ndarray, depth_m: float) -> bool:
        """Cut along the blade's path (P, 3) m, deformed frame, down to `depth_m` under it (P14, §3.5; see
        cutting.cut_along_path); True when the mesh changed.  All or nothing (`apply`)."""
        change = frame.cut_change(self.structure, self.state, path_m, depth_m)
        if change is not None:
            self.apply(change)
        return change is not None

    def apply(self, change: TopologyChange) -> None:
        """Replace the structure and the state by those after `change` (physics.frame.apply_change); when that
        raises, the model is as it was."""
        self.structure, self.state = apply_change(self.structure, self.state, change)

    def reset(self) -> None:
        """Back to the rest shape, at rest, with no tool history and nothing held (physics.state.rest_state); the
        clock and the loads stay."""
        self.state = rest_state(self.structure, len(self.tools), self.state.time_s, self.state.external_forces_n)

    def warm_up(self) -> None:
        """Compile the kernels (numba, cached on disk) before a timed loop starts (physics.frame.warm_up), under the
        cache's lock (base.kernel_cache.compiling), so that processes warming up at once do not corrupt it."""
        with kernel_cache.compiling():
            frame.warm_up(self.structure, self.state, self.tool)
