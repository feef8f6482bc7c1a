"""The solver's regression scenes on the default liver (press, grasp and pull, tear, cut) and their figures: what a
change of the implicit solver must reproduce within its tolerance (test/liver_sim/physics/test_solver_regression.py;
the stored figures come from `python test/support/regression_scenes.py OUT.npz`, run before the solver changed)."""
import contextlib
import sys
from unittest import mock

import numpy as np

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse
from liver_sim.tool.scripts import ScriptSettings, make_script


def _play(model: LiverModel, poses) -> dict:
    """Step `model` through `poses` (None: no tool); the figures: final positions (N, 3) m, the force on the tool
    per frame (F, 3) N and the node count per frame."""
    forces, counts = [], []
    for pose in poses:
        forces.append(model.step_frame(pose).tool_force_n)
        counts.append(len(model.state.positions))
    return {"positions": model.state.positions.copy(), "forces": np.array(forces), "nodes": np.array(counts)}


def _scripted(mode: str, script: str, frames: int, params: ModelParams, **settings) -> dict:
    liver = default_liver()
    model = LiverModel(liver, params, Tool(use=ToolUse(mode, cut_depth_m=0.008)))
    trajectory = make_script(script, ScriptSettings(anchor_m=tuple(press_anchor(liver)), **settings))
    period = model.structure.frame_period_s
    return _play(model, [ToolPose(trajectory.position_at(k * period)) for k in range(frames)])


#: The stroke of `press` and `cut`: 12 mm deep, 4 cm long, off the surface after 1.6 s.
STROKE = dict(depth_m=0.012, slide_m=0.04, approach_s=0.2, press_s=0.4, hold_s=0.2, slide_s=0.5, withdraw_s=0.3,
              rest_s=0.4)


def press(params: ModelParams) -> dict:
    """A 12 mm press, slide and release (2 s)."""
    return _scripted("press", "press_slide_release", 300, params, **STROKE)


def cut(params: ModelParams) -> dict:
    """The same stroke cutting, cut when the tool leaves the surface (2 s)."""
    return _scripted("cut", "press_slide_release", 300, params, **STROKE)


def grasp(params: ModelParams) -> dict:
    """The dome grasped and pulled 8 cm up over 400 frames, tearing on."""
    liver = default_liver()
    model = LiverModel(liver, params.with_changes(tearing=True),
                       Tool(use=ToolUse("grasp", grasp_margin_m=0.005)))
    start = press_anchor(liver) + [0.0, 0.0, model.tool.shape.radius_m - 0.004]
    model.grasp(ToolPose(start))
    return _play(model, [ToolPose(start + [0.0, 0.0, 0.08 * min(1.0, k / 400)]) for k in range(450)])


def tear(params: ModelParams) -> dict:
    """The left lobe's tip pulled by 60 N (the paper's constants and scene), tearing on, 60 frames."""
    liver = default_liver()
    model = LiverModel(liver, params.with_changes(tearing=True, spring_constants="paper", support="paper"))
    group = np.argsort(-liver.points[:, 0])[:15]
    model.state.external_forces_n[group, 0] = 60.0 / len(group)
    return _play(model, [None] * 60)


def press_fem(params: ModelParams) -> dict:
    """`press` with the parenchyma as co-rotational tetrahedra."""
    return press(params.with_changes(tissue_law="fem"))


SCENES = {"press": press, "press_fem": press_fem, "grasp": grasp, "tear": tear, "cut": cut}


def run_scenes(params: ModelParams | None = None) -> dict:
    """{scene: figures} of every scene with `params` (default: ModelParams())."""
    return {name: scene(params or ModelParams()) for name, scene in SCENES.items()}


def flatten(figures: dict) -> dict:
    """{'scene/figure': array} for np.savez."""
    return {f"{scene}/{key}": value for scene, values in figures.items() for key, value in values.items()}


@contextlib.contextmanager
def tight_solves(tolerance: float = 1e-9):
    """A context in which every ImplicitEuler solves its steps, and the tool's compliance, to `tolerance` with no
    absolute floor: the scenes' exact answer (the compliance's path into the physics: a cut follows the local model's
    contact)."""
    from liver_sim.physics.solver import implicit

    init = implicit.ImplicitEuler.__init__

    def tight(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.cg_tolerance = tolerance

    with mock.patch.object(implicit.ImplicitEuler, "__init__", tight), \
            mock.patch.object(implicit, "COMPLIANCE_TOLERANCE", tolerance), \
            mock.patch.object(implicit, "CG_FLOOR_OF_NEWTON", 0.0):
        yield


if __name__ == "__main__":  # today's figures, and the same solved to 1e-9 under "tight/"
    stored = flatten(run_scenes())
    with tight_solves():
        stored.update({f"tight/{key}": value for key, value in flatten(run_scenes()).items()})
    np.savez_compressed(sys.argv[1], **stored)
