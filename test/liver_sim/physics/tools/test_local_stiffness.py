"""K of the haptic local model (physics.tools.local_stiffness): the touching probes' penalties in series with the
tissue's compliance, by hand; the tool's unit load pattern; and K refreshed every few frames staying near a fresh
solve on the default liver."""
import numpy as np
import pytest

from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, probe_contacts, tool_sweep
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.local_stiffness import contact_load, local_stiffness, touching_probes
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
    penalty = cached.structure.params.contact_stiffness_n_per_m
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



def pressed_default_liver(frames: int = 30) -> LiverModel:
    """The default liver with its tool pressed 6 mm into the press anchor over `frames` frames."""
    from liver_sim.mesh.landmarks import press_anchor
    from liver_sim.mesh.liver_shape import default_liver

    mesh = default_liver()
    model = LiverModel(mesh, ModelParams())
    anchor, radius = press_anchor(mesh), model.tool.shape.radius_m
    for k in range(frames):
        model.step_frame(ToolPose(anchor + [0.0, 0.0, radius - 0.006 * (k + 1) / frames]))
    return model


def test_a_compliance_solve_in_slices_makes_the_iterations_of_one_solve():
    model = pressed_default_liver()
    solver, state, tool = model.structure.solver, model.state, model.state.tools[0]
    load = contact_load(tool.sweep, len(state.positions))
    guesses = [np.zeros_like(state.positions) for _ in range(2)]
    whole, sliced = (solver.compliance_solve(solver.workspace(), state.positions, state.inv_mass, load, 3.0, guess)
                     for guess in guesses)
    at_once = whole.finish()
    slices = 0
    while not sliced.advance(3):
        slices += 1
    assert slices > 3 and sliced.iterations == whole.iterations
    assert sliced.finish() == at_once > 0.0
    np.testing.assert_array_equal(guesses[0], guesses[1])


def test_k_takes_the_solve_begun_solve_frames_before_at_the_frame_it_is_due():
    """In contact, a solve is begun SOLVE_FRAMES frames before it is due and taken at the due frame, REFRESH_FRAMES
    after the last: K changes at that frame only, to the compliance of the positions where the solve was begun."""
    from liver_sim.mesh.landmarks import press_anchor
    from liver_sim.physics.tools.local_stiffness import REFRESH_FRAMES, SOLVE_FRAMES

    model = pressed_default_liver()
    solver, tool = model.structure.solver, model.state.tools[0]
    anchor, radius = press_anchor(model.structure.mesh), model.tool.shape.radius_m
    assert tool.frames_since_solve < REFRESH_FRAMES and tool.compliance_m_per_n is not None
    begun, taken, compliance = [], [], tool.compliance_m_per_n
    for k in range(3 * REFRESH_FRAMES):
        model.step_frame(ToolPose(anchor + [0.0, 0.0, radius - 0.006 - 0.002 * (k + 1) / REFRESH_FRAMES]))
        if tool.frames_since_solve == REFRESH_FRAMES - SOLVE_FRAMES:
            assert tool.compliance_solve is not None
            positions = model.state.positions
            begun.append((positions.copy(), contact_load(tool.sweep, len(positions)), tool.compliance_guess.copy()))
        if tool.compliance_m_per_n != compliance:
            assert tool.frames_since_solve == 0 and tool.compliance_solve is None
            if begun:  # (the first may have been begun before the loop)
                positions, load, guess = begun[-1]
                assert tool.compliance_m_per_n == solver.compliance(
                    positions, model.state.inv_mass, load, model.structure.params.environment_damping_per_s, guess)
            taken.append(k)
            compliance = tool.compliance_m_per_n
    assert len(taken) >= 3 and len(begun) >= 2 and np.all(np.diff(taken) == REFRESH_FRAMES)
