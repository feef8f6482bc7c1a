"""Pulls of the topology and tool tests: a bar held at one end and pulled by the other (explicit steps, the paper's
constants), and the default liver's dome grasped and pulled up."""
import math

import numpy as np

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse

from meshes import box_mesh

SPACING_M = 0.02

NX, NY, NZ = 10, 3, 3



def bar_params(**changes):
    bar = box_mesh(NX, NY, NZ, SPACING_M)
    fixed = tuple(np.flatnonzero(bar.points[:, 0] < 1e-9).tolist())
    # the pulls below were set for the paper's per-spring constants and an explicit step
    params = ModelParams(fixed_nodes=fixed, spring_constants="paper", integrator="symplectic_euler", **changes)
    stable = LiverModel(bar, params).structure.stable_dt_s
    return bar, params.with_changes(substeps=math.ceil(1.0 / (params.frame_rate_hz * 0.6 * stable)))



def pulled_bar(force_n, **changes):
    """The bar, left end fixed, its last layer of cubes pulled along +x (force ∝ node mass)."""
    bar, params = bar_params(**changes)
    model = LiverModel(bar, params)
    pulled = model.structure.masses_kg * (bar.points[:, 0] > (NX - 1) * SPACING_M - 1e-9)
    model.state.external_forces_n[:, 0] = force_n * pulled / pulled.sum()
    return model



def pull_the_dome(tearing):
    """The default liver grasped at its dome and pulled 8 cm up over 400 frames; (model, tool use, results,
    tool tips)."""
    liver = default_liver()
    model = LiverModel(liver, ModelParams(tearing=tearing), Tool(use=ToolUse("grasp", grasp_margin_m=0.005)))
    dome = press_anchor(liver)
    start = dome + [0.0, 0.0, model.tool.shape.radius_m - 0.004]
    assert model.grasp(ToolPose(start)) > 0
    tips = [start + [0.0, 0.0, 0.08 * min(1.0, k / 400)] for k in range(450)]
    return model, model.tool.use, [model.step_frame(ToolPose(tip)) for tip in tips], tips

