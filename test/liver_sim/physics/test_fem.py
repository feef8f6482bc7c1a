"""The default liver with tissue_law 'fem' or 'neo_hookean' as a whole model: pressed, cut and torn (the elements'
laws: tissue/test_fem_kernels.py, tissue/test_neo_hookean.py)."""
import numpy as np
import pytest

from liver_sim.mesh.landmarks import press_anchor, upper_skin_path
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams


@pytest.mark.parametrize("law", ("fem", "neo_hookean"))
def test_the_liver_with_elements_is_pressed_cut_and_torn(law):
    mesh = default_liver()
    model = LiverModel(mesh, ModelParams(tissue_law=law, tearing=True))
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
    assert model.structure.solver.tets.neo_hookean == (law == "neo_hookean")  # the cut kept the law
    for _ in range(30):
        result = model.step_frame(None)
    assert result.divergence is None and np.isfinite(model.state.positions).all()


