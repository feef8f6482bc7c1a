"""haptic_bridge.intake without ROS: a device sample counts only once it is usable (decoded, in the workspace, not
stamped in the future), so the pose age is the age of the newest usable one; every scale the loop may render with
is known for the K·scale check; a device clock stepping back restarts the passivity observer's reference."""
import math

import numpy as np

from haptic_bridge.intake import Intake
from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.passivity import PassivityObserver
from haptic_bridge.tick import BridgeTick
from liver_sim.base.geometry.device_map import DeviceMap
from msg_defs.cdr import encode
from msg_defs.poses import position_from_bytes

CLOCK_S = 1000.0  # the device stamps' clock now (s)


def pose_bytes(position, stamp_s: float = CLOCK_S) -> bytes:
    sec = int(stamp_s)
    return encode(sec, int(round((stamp_s - sec) * 1e9)), "phantom_base", (*position, 0.0, 0.0, 0.0, 1.0))


def setup(**changes):
    p = BridgeParameters.defaults().replace(**changes)
    tick = BridgeTick(p, device_map=DeviceMap())
    return Intake(p, {"device_pose": position_from_bytes}), tick


def test_a_usable_sample_places_the_tip_and_is_fresh():
    intake, tick = setup()
    intake.offer("device_pose", pose_bytes((0.0, 0.0, 0.01)), received_s=10.0)
    tip, pose_age, *_ = intake.tick_inputs(tick, 10.001, CLOCK_S)
    assert np.allclose(tip, (0.0, 0.0, 0.01)) and math.isclose(pose_age, 0.001)


def test_a_sample_50_m_away_counts_as_no_sample_and_the_pose_ages():
    intake, tick = setup()
    intake.offer("device_pose", pose_bytes((0.0, 0.0, 0.01)), received_s=10.0)
    intake.tick_inputs(tick, 10.0, CLOCK_S)
    intake.offer("device_pose", pose_bytes((50.0, 0.0, 0.0)), received_s=10.5)
    _, pose_age, *_ = intake.tick_inputs(tick, 10.5, CLOCK_S)
    assert pose_age == 0.5 and pose_age > tick.p.lifetime_s, "the watchdog sees the device as silent"
    assert intake.bad["device_pose"] == 1 and "workspace" in intake.reasons["device_pose"]


def test_a_sample_stamped_ahead_of_the_clock_beyond_the_tolerance_is_refused():
    intake, tick = setup()
    intake.offer("device_pose", pose_bytes((0.0, 0.0, 0.01), CLOCK_S + 1.0), received_s=10.0)
    tip, pose_age, *_ = intake.tick_inputs(tick, 10.0, CLOCK_S)
    assert tip is None and pose_age == math.inf
    assert intake.bad["device_pose"] == 1 and "ahead of the clock" in intake.reasons["device_pose"]
    intake.offer("device_pose", pose_bytes((0.0, 0.0, 0.01), CLOCK_S + 0.01), received_s=10.1)  # within 50 ms
    assert intake.tick_inputs(tick, 10.1, CLOCK_S)[0] is not None


def test_every_scale_the_loop_may_render_with_is_checked_and_a_non_passive_map_is_withdrawn():
    intake, tick = setup(stiffness_n_per_m=90.0)
    assert intake.offer_map(DeviceMap(scale=2.0), "/liver_tool") is None
    assert 2.0 in intake.scales(tick), "the newest map, not yet taken by the loop, counts"
    strict, _ = setup()
    problem = strict.offer_map(DeviceMap(scale=2.0), "/liver_tool")  # K 190 · 2 is beyond the passive limit
    assert problem.startswith("device map refused") and strict.newest_map is None


def test_a_device_clock_stepping_back_restarts_the_observers_reference_instead_of_freezing_it():
    observer = PassivityObserver(0.001)
    observer.commanded(0.0, np.array([0.0, 0.0, 1.0]))
    observer.sample(100.000, 100.000, (0.0, 0.0, 0.0))
    observer.sample(100.001, 100.001, (0.0, 0.0, 0.001))
    before = observer.energy_j
    observer.sample(50.000, 50.000, (0.0, 0.0, 0.001))  # the clock stepped back 50 s
    observer.sample(50.001, 50.001, (0.0, 0.0, 0.002))
    assert observer.energy_j > before, "later samples still count"
