"""K of the haptic local model (physics.tools.local_stiffness): the touching probes' penalties in series with the
tissue's compliance, by hand; the tool's unit load pattern and its rows' one-frame stiffness; K refreshed every few
frames staying near a fresh solve on the default liver; and K against what one frame of the physics answers to a
small move of the tool."""
import copy

import numpy as np
import pytest

from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, probe_contacts, tool_sweep
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.local_stiffness import contact_load, local_stiffness, row_stiffness, touching_probes
from liver_sim.physics.tools.tool import Tool

#: One skin triangle in the plane z = 0, facing +z (the liver below it).
TRIANGLE = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])


def test_the_penalties_and_the_tissue_act_in_series():
    # 1/K = 1/(probes·λ) + c: 1/(2·100) + 0.005 = 0.01 m/N, K = 100 N/m
    assert local_stiffness(100.0, 2.0, 0.005) == pytest.approx(100.0)
    assert local_stiffness(100.0, 1.5, 0.0) == pytest.approx(150.0)  # a rigid tissue: the penalties alone
    assert local_stiffness(100.0, 1.0, -1.0) == pytest.approx(100.0)  # a negative compliance counts as none


def swept(tip):
    """A sphere of 1 cm at `tip` over TRIANGLE with the rows of a step at rest."""
    sweep = tool_sweep(ToolShape(radius_m=0.01), ToolPose(np.array(tip)), None, ModelParams(), 0.05, TRIANGLE,
                       np.array([[0, 1, 2]]))
    probe_contacts(TRIANGLE, np.zeros((3, 3)), sweep, np.zeros(3), 0.0)
    return sweep


def test_the_load_pattern_is_a_unit_push_spread_by_the_weights():
    touching = swept([0.02, 0.03, 0.006])  # 4 mm deep, q = 0.5·a + 0.2·b + 0.3·c
    assert touching_probes(touching) == pytest.approx(1.0)
    np.testing.assert_allclose(contact_load(touching, 3), [[0, 0, -0.5], [0, 0, -0.2], [0, 0, -0.3]], atol=1e-14)
    near = swept([0.02, 0.03, 0.02])  # 1 cm above the skin: no row touches, the nearest one is loaded
    assert touching_probes(near) == 1.0
    np.testing.assert_allclose(contact_load(near, 3).sum(axis=0), [0.0, 0.0, -1.0], atol=1e-14)
    away = tool_sweep(ToolShape(), None, None, ModelParams(), 0.05, TRIANGLE, np.array([[0, 1, 2]]))
    assert touching_probes(away) == 0.0 and not contact_load(away, 3).any()


def test_the_local_stiffness_refreshed_every_few_frames_stays_near_a_fresh_solve():
    """K is solved every REFRESH_FRAMES frames and reused in between: over a press and slide on the
    default liver it stays within 10 % of K solved afresh at each frame (a twin model)."""
    from liver_sim.mesh.landmarks import press_anchor
    from liver_sim.mesh.liver_shape import default_liver
    from liver_sim.physics.tools.local_stiffness import REFRESH_FRAMES
    from liver_sim.tool.scripts import ScriptSettings, make_script

    mesh = default_liver()
    cached = LiverModel(mesh, ModelParams())
    fresh = LiverModel(mesh, ModelParams(), Tool(stiffness_refresh_frames=1))
    script = make_script("press_slide_release", ScriptSettings(anchor_m=tuple(press_anchor(mesh)), rest_s=0.1))
    params = cached.structure.params
    penalty = params.contact_stiffness_n_per_m + params.contact_damping_ns_per_m * params.frame_rate_hz  # λ + μ/T
    compared = 0
    for k in range(int(script.duration_s * 150)):
        pose = ToolPose(script.position_at(k / 150.0))
        reused, solved = cached.step_frame(pose).local_model, fresh.step_frame(pose).local_model
        np.testing.assert_array_equal(cached.state.positions, fresh.state.positions)  # K does not touch the physics
        if not solved.in_contact:
            continue
        assert reused.stiffness_n_per_m == pytest.approx(solved.stiffness_n_per_m, rel=0.10), k
        assert solved.stiffness_n_per_m < penalty
        compared += 1
    assert REFRESH_FRAMES > 1 and compared > 50



def test_the_rows_one_frame_stiffness_is_k_plus_c_over_the_frame_along_their_push():
    """Two pushing rows along +z (k 100 and 200 N/m, c 1 N·s/m each, T 0.01 s: 100 + 100 and 200 + 100 N/m) and one
    apart: K = 500 N/m; the load pattern is each pushing row's answer, spread by its weights, summing to a unit push."""
    x = np.zeros((3, 3))
    rows = Contacts(np.array([[0, -1, -1], [1, 2, -1], [2, -1, -1]]),
                    np.array([[1.0, 0.0, 0.0], [0.5, 0.5, 0.0], [1.0, 0.0, 0.0]]), np.tile([0.0, 0.0, 1.0], (3, 1)),
                    np.array([0.001, 0.002, -0.001]), np.zeros(3), np.array([100.0, 200.0, 100.0]), np.ones(3))
    stiffness, load = row_stiffness(rows, x, np.zeros_like(x), 0.01)
    assert stiffness == pytest.approx(500.0)
    np.testing.assert_allclose(load, [[0, 0, 0.4], [0, 0, 0.3], [0, 0, 0.3]], atol=1e-15)
    assert row_stiffness(Contacts.none(), x, x, 0.01) == (0.0, pytest.approx(np.zeros((3, 3))))


@pytest.mark.parametrize("depth_mm", [2.0, 5.0, 8.0])
def test_the_local_stiffness_is_what_one_frame_answers_to_a_small_move(depth_mm):
    """Held at a depth on the default liver, the local model's K against the physics' own answer to the tool moved
    ±0.05 mm along its push for one frame (central difference over two copies of the model): within 20 %."""
    from liver_sim.mesh.landmarks import press_anchor
    from liver_sim.mesh.liver_shape import default_liver
    mesh = default_liver()
    model = LiverModel(mesh, ModelParams())
    anchor = press_anchor(mesh)
    depth = depth_mm * 1e-3

    def at(d):
        return ToolPose(anchor + np.array([0.0, 0.0, model.tool.shape.radius_m - d]))

    for k in range(1, 91):
        eased = min(k / 60, 1.0)
        result = model.step_frame(at(depth * eased - 0.002 * (1.0 - eased)))
    for _ in range(150):
        result = model.step_frame(at(depth))
    push = result.tool_force_n / np.linalg.norm(result.tool_force_n)
    answers = [copy.deepcopy(model).step_frame(at(depth + step)).tool_force_n @ push for step in (5e-5, -5e-5)]
    one_frame = (answers[0] - answers[1]) / 1e-4
    assert result.local_model.stiffness_n_per_m == pytest.approx(one_frame, rel=0.20)
