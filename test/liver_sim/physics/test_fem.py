"""The default liver with tissue_law 'fem' as a whole model: pressed, cut and torn (the elements' law:
tissue/test_fem_kernels.py)."""
import numpy as np

from liver_sim.mesh.landmarks import press_anchor, upper_skin_path
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams


def test_the_liver_with_elements_is_pressed_cut_and_torn():
    mesh = default_liver()
    model = LiverModel(mesh, ModelParams(tissue_law="fem", tearing=True))
    anchor = press_anchor(mesh)
    radius = model.tool.shape.radius_m
    for frame in range(60):
        depth = min(frame, 30) / 30 * 0.01
        result = model.step_frame(ToolPose(anchor + np.array([0.0, 0.0, radius - depth])))
    assert result.divergence is None and result.tool_force_n[2] > 0.05
    assert result.local_model.valid and result.local_model.in_contact
    path = upper_skin_path(mesh, (-0.08, 0.0), (-0.02, 0.0))
    assert model.cut(path, 0.01)
    assert len(model.structure.solver.tets.tets) == len(model.structure.mesh.tets) > len(mesh.tets)
    for _ in range(30):
        result = model.step_frame(None)
    assert result.divergence is None and np.isfinite(model.state.positions).all()


