"""haptic_bridge.inputs: the plausibility of the bridge's inputs, the workspace bound and the size of a force."""
import numpy as np
import pytest

from haptic_bridge.inputs import IMPLAUSIBLE_FORCE_N, InputCheck
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


#: A workspace off the origin, so that the bound is measured from its centre.
CENTRE = np.array([0.1, -0.2, 0.05])


def test_the_workspace_bound_is_the_distance_from_its_centre():
    check = InputCheck(CENTRE, 0.4)
    direction = np.array([2.0, -1.0, 2.0]) / 3.0
    assert check.tip(CENTRE + 0.399999 * direction) is None
    problem = check.tip(CENTRE + 0.400001 * direction)
    assert "tool tip" in problem and "workspace_radius_m=0.4" in problem
    assert check.model(LocalModel.plane(CENTRE + 0.399999 * direction, [0.0, 0.0, 1.0])) is None
    assert "plane point" in check.model(LocalModel.plane(CENTRE + 0.400001 * direction, [0.0, 0.0, 1.0]))
    beside = CENTRE + [0.35, 0.0, 0.0]  # 0.495 m from the origin, 0.35 m from the centre
    assert np.linalg.norm(beside) > 0.4 and check.tip(beside) is None


def test_a_sphere_is_judged_by_its_centre_and_its_radius():
    check = InputCheck(CENTRE, 0.4)
    assert check.model(LocalModel.sphere(CENTRE + [0.0, 0.0, 0.399999], 0.4)) is None
    assert "sphere centre" in check.model(LocalModel.sphere(CENTRE + [0.0, 0.0, 0.400001], 0.05))
    assert "sphere radius 0.400001 m exceeds workspace_radius_m=0.4" in check.model(
        LocalModel.sphere(CENTRE, 0.400001))


def test_a_force_is_plausible_up_to_the_bound_and_finite():
    assert InputCheck.force(np.array([0.0, 0.6, 0.8]) * IMPLAUSIBLE_FORCE_N * 0.999999) is None
    assert "implausible" in InputCheck.force(np.array([0.0, 0.6, 0.8]) * IMPLAUSIBLE_FORCE_N * 1.000001)
    for bad in (np.nan, np.inf, -np.inf):
        assert "not finite" in InputCheck.force(np.array([0.0, bad, 0.0]))


@pytest.mark.parametrize("centre, radius, name", [([0.0, 0.0], 0.4, "workspace_centre_m"),
                                                  ([0.0, np.nan, 0.0], 0.4, "workspace_centre_m"),
                                                  ([0.0, 0.0, 0.0], 0.0, "workspace_radius_m"),
                                                  ([0.0, 0.0, 0.0], np.inf, "workspace_radius_m")])
def test_a_bad_workspace_is_refused_by_name(centre, radius, name):
    with pytest.raises(ValueError, match=f"^{name} must be finite"):
        InputCheck(centre, radius)
