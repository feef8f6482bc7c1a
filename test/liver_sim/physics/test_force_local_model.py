"""The local model is the physics' contact force (paper §2.5, P11): at each physics update the bridge renders
the physics force on the tool, between updates a spring of the tissue's stiffness K (ROS-free, offline)."""
import math

import numpy as np
import pytest

from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.tick import BridgeTick, rendered_stiffness
from liver_sim.base.local_model import LocalModel, penetration
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.tool.scripts import ScriptSettings, make_script
from msg_defs.local_model import local_model_marker, marker_to_local_model
from msg_defs.stamps import stamp_from_seconds

PUSH_N = 0.05


def agree(rendered, physics):
    """Norm within 5 % or 0.01 N, direction within 5° (when either exceeds 0.01 N)."""
    a, b = np.linalg.norm(rendered), np.linalg.norm(physics)
    if abs(a - b) > max(0.05 * b, 0.01):
        return False
    if max(a, b) <= 0.01:
        return True
    return math.degrees(math.acos(np.clip(rendered @ physics / (a * b), -1.0, 1.0))) <= 5.0


@pytest.fixture(scope="module")
def demo_run():
    """The demo's script (press_slide_release, the demo's settings) played on the default liver at the
    physics' 150 Hz, each frame's local model through its Marker, and the haptic bridge with the demo's
    parameters ticking at 1 kHz on the script's tip between the frames."""
    mesh = default_liver()
    model = LiverModel(mesh, ModelParams())
    bridge = BridgeParameters.defaults()
    tick = BridgeTick(bridge)
    script = make_script("press_slide_release", ScriptSettings(anchor_m=tuple(press_anchor(mesh)), rest_s=0.5))
    frames, ticks = [], []
    period, tick_s = model.structure.frame_period_s, 1.0 / bridge.rate_hz
    t = 0.0
    for k in range(int(script.duration_s / period)):
        pose = ToolPose(script.position_at(k * period))
        result = model.step_frame(pose)
        assert result.divergence is None
        local, _ = marker_to_local_model(local_model_marker(result.local_model, stamp_from_seconds(k * period),
                                                            "liver", 0.05))
        frames.append((pose.position, result.tool_force_n, local))
        while t < (k + 1) * period:  # the ticks until the next frame, with this one's model
            command = tick.step(t, script.position_at(t), 0.0, (local, bridge.lifetime_s), t - k * period)
            ticks.append((t, k, command))
            t += tick_s
    return bridge, frames, ticks


def rendered_at(tick, local, tip):
    """The force (N) the bridge renders for the physics' `local` model with the tool at `tip`, the depth rate
    aside: K_r·depth of the model it renders (capped at its stiffness_n_per_m), and that depth."""
    model = tick.rendered_model(local)
    depth, direction = penetration(model, tip, tick.p.tool_radius_m)
    return rendered_stiffness(model, tick.p.stiffness_n_per_m) * depth * direction, depth


def test_at_each_update_the_rendered_force_is_the_physics_force(demo_run):
    bridge, frames, _ = demo_run
    tick = BridgeTick(bridge)
    touching = 0
    for tip, force, local in frames:
        if local is None:
            assert np.linalg.norm(force) == 0.0
            continue
        rendered, depth = rendered_at(tick, local, tip)
        assert agree(rendered, force), (rendered, force)
        touching += np.linalg.norm(force) > 0.05
        if np.linalg.norm(force) == 0.0:
            assert depth == 0.0  # no contact in the physics: none in the local model
        else:
            assert 0.0 < local.stiffness_n_per_m < bridge.stiffness_n_per_m  # the tissue's K, below the cap
    assert touching > 100  # a real press and slide


def test_the_device_is_never_pushed_while_the_physics_has_no_contact(demo_run):
    _, frames, ticks = demo_run
    idle = [np.linalg.norm(command) for _, k, command in ticks if np.linalg.norm(frames[k][1]) == 0.0]
    assert len(idle) > 500 and max(idle) <= PUSH_N


def test_between_updates_the_command_follows_the_physics_force(demo_run):
    """The 1 kHz command one physics period after each update (the model has glided in, the soft start is
    over) is the physics force of that update within the tolerances plus what K × the tip's motion since
    the frame explains."""
    bridge, frames, ticks = demo_run
    checked = 0
    for t, k, command in ticks:
        if t < bridge.soft_start_s + 0.05 or k == 0:
            continue
        tip, force, local = frames[k]
        if local is None or abs(t - k / 150.0 - (1 / 150.0 - 1e-3)) > 1e-3 / 2 or np.linalg.norm(force) < 0.05:
            continue
        stiffness = rendered_stiffness(BridgeTick(bridge).rendered_model(local), bridge.stiffness_n_per_m)
        moved = np.linalg.norm(frames[min(k + 1, len(frames) - 1)][0] - tip)
        assert np.linalg.norm(command - force) <= max(0.05 * np.linalg.norm(force), 0.01) + stiffness * moved \
            + bridge.damping_ns_per_m * 0.2 + 1e-9, (t, command, force)
        checked += 1
    assert checked > 100


def stiffer(local, tip, force, stiffness_n_per_m, tool_radius_m):
    """The physics' model of a frame placed again for a stiffer K, as the physics places it (paper §2.5): the
    surface moved toward the liver along the direction of its push until K·depth at the frame's pose is |F|."""
    depth, direction = penetration(local, tip, tool_radius_m)
    back = depth - float(np.linalg.norm(force)) / stiffness_n_per_m if depth > 0.0 else 0.0
    point = local.point - back * direction
    return LocalModel(local.kind, True, point, local.normal, local.centre if local.kind == "sphere" else point,
                      local.radius_m - back if local.kind == "sphere" else 0.0, depth - back, local.in_contact,
                      stiffness_n_per_m)


def test_a_model_stiffer_than_the_bridges_cap_still_renders_the_physics_force_at_each_update(demo_run):
    """The demo's frames with K = 350 N/m, above the bridge's 190 N/m (the tissue's one-frame stiffness), through
    the Marker: the bridge renders less than K, yet at each update the physics force."""
    bridge, frames, _ = demo_run
    tick = BridgeTick(bridge)
    checked = 0
    for tip, force, local in frames:
        if local is None:
            continue
        stiff = stiffer(local, tip, force, 350.0, bridge.tool_radius_m)
        stiff, _ = marker_to_local_model(local_model_marker(stiff, stamp_from_seconds(0.0), "liver", 0.05))
        assert stiff.stiffness_n_per_m > bridge.stiffness_n_per_m
        rendered, _ = rendered_at(tick, stiff, tip)
        assert agree(rendered, force), (rendered, force)
        checked += np.linalg.norm(force) > 0.05
    assert checked > 100


def test_the_stiffness_travels_in_the_markers_text_and_bad_values_are_refused_by_name():
    from liver_sim.base.local_model import LocalModel

    plane = LocalModel("plane", True, [0.0, 0.0, 0.1], [0.0, 0.0, 1.0], [0.0, 0.0, 0.1], 0.0, 0.002, True, 34.5)
    marker = local_model_marker(plane, stamp_from_seconds(0.0), "liver", 0.05)
    assert marker.text == "stiffness_n_per_m=34.5 depth_m=0.002"
    assert marker_to_local_model(marker)[0].stiffness_n_per_m == 34.5
    assert marker_to_local_model(marker)[0].depth_m == 0.002  # K·depth: the physics force
    marker.text = ""
    assert marker_to_local_model(marker)[0].stiffness_n_per_m is None  # rendered with the bridge's own K
    marker.text = "stiffness_n_per_m=nan"
    with pytest.raises(ValueError, match="Marker.text stiffness_n_per_m"):
        marker_to_local_model(marker)
    with pytest.raises(ValueError, match="LocalModel.stiffness_n_per_m"):
        LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], -1.0)


def test_the_bridge_renders_the_models_stiffness_capped_at_its_own():
    from liver_sim.base.local_model import LocalModel

    bridge = BridgeParameters.defaults()
    tip = np.array([0.0, 0.0, bridge.tool_radius_m - 0.002])  # 2 mm into the plane z = 0
    for own, expected in ((40.0, 40.0), (1e4, bridge.stiffness_n_per_m), (None, bridge.stiffness_n_per_m)):
        tick = BridgeTick(bridge.replace(model_glide_s=0.0, damping_ns_per_m=0.0))
        force = tick.render(LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], own), tip)
        np.testing.assert_allclose(force, [0.0, 0.0, expected * 0.002])
