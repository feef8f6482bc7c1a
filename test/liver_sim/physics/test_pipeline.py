"""The physics frame pipeline (no ROS): pose gate, pose timeout, tool use, surface flag, marker decimation."""
import subprocess
import sys

import numpy as np
import pytest

from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.tetmesh import MeshError
from liver_sim.physics.parameters import PhysicsParameters, build_model
from liver_sim.physics.pipeline import FramePipeline
from liver_sim.tool.scripts import ScriptSettings, make_script

from meshes import assert_same_state, fail_topology_changes


def values(**changes):
    return PhysicsParameters.defaults().replace(**changes)


@pytest.fixture(scope="module")
def defaults():
    return values()


def test_poses_outside_the_workspace_are_refused_and_counted(defaults):
    pipeline = FramePipeline(build_model(defaults), defaults)
    upper = pipeline.model.structure.mesh.bounds[1]
    assert pipeline.receive(upper + [0.0, 0.0, 0.29], (0, 0, 0, 1), 0.0) is not None
    assert pipeline.receive(upper + [0.0, 0.0, 0.31], (0, 0, 0, 1), 0.001) is None
    pipeline.refuse("malformed", 0.002)
    assert pipeline.refused_poses == 2
    events = pipeline.step(0.003).events
    assert [e.kind for e in events] == ["refused", "refused"] and "outside the workspace" in events[0].text
    assert not pipeline.step(0.01).events  # reported once


def test_a_pose_older_than_the_timeout_means_no_tool(defaults):
    pipeline = FramePipeline(build_model(defaults), defaults)
    top = press_anchor(pipeline.model.structure.mesh)
    pipeline.receive(top, (0, 0, 0, 1), 0.0)  # the tool sphere's centre on the skin: in contact
    assert pipeline.step(defaults.tool_pose_timeout_s).result.local_model.valid
    assert not pipeline.step(defaults.tool_pose_timeout_s + 0.001).result.local_model.valid


def test_the_marker_is_due_at_marker_rate_hz(defaults):
    pipeline = FramePipeline(build_model(defaults), defaults)
    due = [pipeline.step(0.0).marker_due for _ in range(10)]
    assert due == [True, False, False, False, False, True, False, False, False, False]  # 150 Hz / 30 Hz
    assert pipeline.frames == 10


def test_a_cut_flags_the_surface_and_is_logged():
    cut = values(tool_mode="cut", cut_depth_m=0.012)
    pipeline = FramePipeline(build_model(cut), cut)
    liver = pipeline.model.structure.mesh
    script = make_script("press_slide_release", ScriptSettings(anchor_m=tuple(press_anchor(liver)), depth_m=0.012,
                                                               slide_m=0.06, slide_s=3.0, rest_s=0.5))
    period = pipeline.model.structure.frame_period_s
    frames = []
    for k in range(int(script.duration_s / period)):
        pipeline.receive(script.position_at(k * period), (0, 0, 0, 1), k * period)
        frames.append(pipeline.step(k * period))
    changed = [f for f in frames if f.surface_changed]
    assert len(changed) == 1 == pipeline.model.structure.version
    assert [e.kind for e in changed[0].events] == ["topology"] and changed[0].events[0].text.startswith("cut: ")
    assert len(pipeline.model.state.positions) > len(liver.points)


def test_build_model_loads_mesh_path_scaled_by_mesh_scale(tmp_path):
    from meshes import write_sphere_surface

    path = write_sphere_surface(tmp_path / "sphere_mm.obj", 40.0, centre=(100.0, -50.0, 20.0), subdivisions=2)
    unitless = values(mesh_path=str(path), target_tets=300)
    with pytest.raises(MeshError, match=r"sphere_mm.obj: implausible size .*mesh_scale.*--scale 0\.001 "):
        build_model(unitless)
    model = build_model(unitless.replace(mesh_scale=0.001))
    lower, upper = model.structure.mesh.bounds
    np.testing.assert_allclose((lower + upper) / 2, [0.1, -0.05, 0.02], atol=2e-3)
    np.testing.assert_allclose(upper - lower, [0.08] * 3, rtol=0.08)
    in_metres = load_mesh(write_sphere_surface(tmp_path / "sphere_m.obj", 0.04, centre=(0.1, -0.05, 0.02),
                                               subdivisions=2), 300)
    assert len(model.structure.mesh.tets) == len(in_metres.tets)  # the same organ as written in metres
    assert model.structure.mesh.volume == pytest.approx(in_metres.volume, rel=1e-3)  # the OBJ keeps 8 decimals


def test_a_cut_failing_midway_leaves_the_model_as_it_was_is_counted_and_the_frames_go_on(monkeypatch):
    cut = values(tool_mode="cut", cut_depth_m=0.012)
    pipeline = FramePipeline(build_model(cut), cut)
    model = pipeline.model
    before = fail_topology_changes(monkeypatch)
    script = make_script("press_slide_release", ScriptSettings(
        anchor_m=tuple(press_anchor(model.structure.mesh)), depth_m=0.012, slide_m=0.03, approach_s=0.1, press_s=0.3,
        hold_s=0.05, slide_s=0.5, withdraw_s=0.1, rest_s=0.2))
    period = model.structure.frame_period_s
    for k in range(int(script.duration_s / period)):
        pipeline.receive(script.position_at(k * period), (0, 0, 0, 1), k * period)
        frame = pipeline.step(k * period)
        if before:
            break
    assert len(before) == 1 and pipeline.topology_failures == 1
    assert_same_state(before[0], model)
    assert not frame.surface_changed and not frame.result.topology_changed
    failed = [e.text for e in frame.events if e.kind == "topology_failed"]
    assert len(failed) == 1 and "RuntimeError: injected" in failed[0]
    for j in range(k + 1, k + 5):
        pipeline.receive(script.position_at(j * period), (0, 0, 0, 1), j * period)
        assert pipeline.step(j * period).result.divergence is None
    assert np.isfinite(model.state.positions).all() and pipeline.topology_failures == 1


def test_the_pipeline_and_the_offline_parameters_import_no_ros():
    code = ("import sys, liver_sim.physics.pipeline, liver_sim.sessions.parameters; "
            "print(sorted(m for m in sys.modules if m.startswith('rclpy') or m.startswith('liver_sim.nodes')))")
    imported = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert imported.strip() == "[]"
