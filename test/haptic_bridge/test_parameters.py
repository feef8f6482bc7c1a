"""haptic_bridge.parameters: the bridge's parameter table and its typed record, which the node and the offline
sessions both read, so both refuse the same values: a bridge starts from the defaults, the clamp stays within the
PHANToM's peak, the topics are relative (a bridge in a namespace takes them there), a wrong name or choice fails
where the values are read."""
import pytest

from haptic_bridge.parameters import MODES, PARAMETERS, BridgeParameters
from haptic_bridge.safety import DEFAULT_MAX_FORCE_N, PHANTOM_MAX_FORCE_N, SafeForceOutput
from haptic_bridge.tick import BridgeTick, passivity_problem

DEFAULTS = BridgeParameters.defaults()


def test_a_bridge_starts_from_the_defaults():
    assert passivity_problem(DEFAULTS) is None
    tick = BridgeTick(DEFAULTS)
    assert isinstance(tick.safety, SafeForceOutput) and tick.safety.max_force == DEFAULT_MAX_FORCE_N
    # the rate limit follows the watchdog's ramp from the clamp to zero (safety.SafeForceOutput)
    assert DEFAULTS.max_force_rate_n_per_s * DEFAULTS.ramp_time_s >= DEFAULTS.max_force_n


def test_the_clamp_may_be_set_up_to_the_phantoms_peak_and_not_beyond():
    assert DEFAULTS.replace(max_force_n=PHANTOM_MAX_FORCE_N).max_force_n == PHANTOM_MAX_FORCE_N
    with pytest.raises(ValueError, match=r"^parameter max_force_n=3\.3000001 is outside"):
        DEFAULTS.replace(max_force_n=3.3000001)
    with pytest.raises(ValueError, match=r"^parameter max_force_n=0\.0 is outside"):
        DEFAULTS.replace(max_force_n=0.0)


def test_the_local_model_is_a_plane_a_sphere_or_none():
    assert MODES == ("plane", "sphere", "none")
    for mode in MODES:
        assert DEFAULTS.replace(local_model=mode).local_model == mode
    with pytest.raises(ValueError, match=r"^parameter local_model='cube' must be one of"):
        DEFAULTS.replace(local_model="cube")


def test_the_topics_are_relative_so_that_a_namespaced_bridge_takes_its_own():
    topics = {name: spec.default for name, spec in PARAMETERS.items() if name.endswith("_topic")}
    assert set(topics) == {"device_map_topic", "force_topic", "measured_cp_topic", "local_model_topic",
                           "tool_wrench_topic"}
    absolute = {name: topic for name, topic in topics.items() if topic.startswith("/") or not topic}
    assert not absolute


def test_a_misspelt_name_or_a_value_of_another_type_fails_where_the_values_are_read():
    with pytest.raises(ValueError, match="unknown parameter.*stiffnes_n_per_m"):
        DEFAULTS.replace(stiffnes_n_per_m=100.0)
    with pytest.raises(ValueError, match=r"^parameter passivity_control='yes' must be a bool"):
        DEFAULTS.replace(passivity_control="yes")
    values = DEFAULTS.as_dict()
    del values["stall_bound_s"]
    with pytest.raises(ValueError, match="missing parameter.*stall_bound_s"):
        BridgeParameters.from_values(values)
