"""haptic_bridge.inputs: the plausibility of the bridge's inputs, the workspace bound and the size of a force."""
import numpy as np

from haptic_bridge.inputs import InputCheck
from liver_sim.base.local_model import LocalModel


def test_inputs_outside_the_workspace_are_refused():
    check = InputCheck([0.0, 0.0, 0.0], 0.4)
    assert check.tip(np.array([0.1, 0.0, 0.0])) is None
    assert "beyond workspace_radius_m" in check.tip(np.array([50.0, 0.0, 0.0]))
    assert "not finite" in check.tip(np.array([np.nan, 0.0, 0.0]))
    assert check.model(LocalModel.plane([0.0, 0.0, 0.1], [0.0, 0.0, 1.0])) is None
    assert "plane point" in check.model(LocalModel.plane([0.0, 0.0, 9.0], [0.0, 0.0, 1.0]))
    assert "radius" in check.model(LocalModel.sphere([0.0, 0.0, 0.0], 3.0))
    assert check.model(None) is None and check.model(LocalModel.invalid()) is None
    assert "implausible" in check.force(np.array([0.0, 0.0, 1e6]))
    assert check.force(np.array([0.0, 0.0, 2.0])) is None
