"""What `bench loop`'s processes cost against the floor of the same invocation: the ratios from given shares, with
one and two tools, without a floor and with a role missing, and the targets judged by the ratio, not the share."""
import json
import math

import pytest

from liver_sim.bench.loop import COST_TARGETS, cost_ratios, cpu_shares

SIDES = ["haptic_bridge", "liver_tool"]
FLOOR = {"source": 0.25, "relay": 0.0625, "loop": 0.25}


def one_tool(physics=0.25, bridge=0.125, tool=0.125, phantom=0.125):
    return {"liver_physics": physics, "haptic_bridge": bridge, "liver_tool": tool, "phantom_sim": phantom,
            "listener": 0.5}


def test_the_ratios_are_the_shares_over_the_floors_matching_roles():
    figures, met = cost_ratios(one_tool(), FLOOR, SIDES, ["phantom_sim"])
    assert figures == {"physics_bridge_tool_cores": 0.5, "phantom_sim_cores": 0.125,
                       "physics_bridge_tool_over_floor_loop": 2.0, "phantom_sim_over_floor_source": 0.5}
    assert met == {"physics_bridge_tool_over_floor_loop_max": True, "phantom_sim_over_floor_source_max": True}
    assert set(met) == set(COST_TARGETS)  # one tool: the targets' own names


def test_two_tools_share_the_floors_loop_once_per_tool_and_each_phantom_is_judged_alone():
    shares = {"liver_physics": 0.5, "haptic_bridge_left": 0.25, "liver_tool_left": 0.125,
              "haptic_bridge_right": 0.25, "liver_tool_right": 0.125, "phantom_sim_left": 0.25,
              "phantom_sim_right": 0.5}
    sides = ["haptic_bridge_left", "liver_tool_left", "haptic_bridge_right", "liver_tool_right"]
    figures, met = cost_ratios(shares, FLOOR, sides, ["phantom_sim_left", "phantom_sim_right"])
    assert figures["physics_bridge_tool_cores"] == 1.25
    assert figures["physics_bridge_tool_over_floor_loop"] == 1.25 / (0.25 * 2)
    assert figures["phantom_sim_left_over_floor_source"] == 1.0
    assert figures["phantom_sim_right_over_floor_source"] == 2.0
    assert met == {"physics_bridge_tool_over_floor_loop_max": True, "phantom_sim_left_over_floor_source_max": True,
                   "phantom_sim_right_over_floor_source_max": False}


def test_the_targets_are_judged_by_the_ratio_not_by_the_share():
    """The same shares meet the targets on a machine whose bare hops cost as much, and miss them on one whose bare
    hops cost a fifth: the absolute shares stand beside the ratios, unjudged."""
    shares = one_tool(physics=0.5, bridge=0.375, tool=0.125, phantom=0.3)
    slow = {"source": 0.25, "loop": 0.5}
    fast = {"source": 0.05, "loop": 0.1}
    figures, met = cost_ratios(shares, slow, SIDES, ["phantom_sim"])
    assert (figures["physics_bridge_tool_over_floor_loop"], figures["phantom_sim_over_floor_source"]) == (2.0, 1.2)
    assert all(met.values())
    figures, met = cost_ratios(shares, fast, SIDES, ["phantom_sim"])
    assert figures["physics_bridge_tool_over_floor_loop"] == pytest.approx(10.0)
    assert figures["phantom_sim_over_floor_source"] == pytest.approx(6.0)
    assert not any(met.values())
    assert figures["physics_bridge_tool_cores"] == 1.0 and figures["phantom_sim_cores"] == 0.3  # beside, both runs


@pytest.mark.parametrize("limit, ratio", [("physics_bridge_tool_over_floor_loop_max", 4.0),
                                          ("phantom_sim_over_floor_source_max", 1.3)])
def test_a_ratio_at_its_target_meets_it_and_one_above_does_not(limit, ratio):
    assert COST_TARGETS[limit] == ratio
    for factor, expected in ((1.0, True), (1.01, False)):
        floor = {"loop": 0.5 / (ratio * factor), "source": 0.125 / (ratio * factor)}
        _, met = cost_ratios(one_tool(), floor, SIDES, ["phantom_sim"])
        assert met[limit] is expected


def test_without_a_floor_the_ratios_are_none_and_not_judged():
    figures, met = cost_ratios(one_tool(), None, SIDES, ["phantom_sim"])
    assert figures["physics_bridge_tool_over_floor_loop"] is None and figures["phantom_sim_over_floor_source"] is None
    assert figures["physics_bridge_tool_cores"] == 0.5 and figures["phantom_sim_cores"] == 0.125
    assert met == {}
    json.dumps(figures)


@pytest.mark.parametrize("shares, floor, nan", [
    (one_tool(), {"loop": 0.25}, "phantom_sim_over_floor_source"),  # the floor without its source
    (one_tool(), {"source": 0.25, "loop": 0.0}, "physics_bridge_tool_over_floor_loop"),  # a floor share of nothing
    ({k: v for k, v in one_tool().items() if k != "liver_tool"}, FLOOR,
     "physics_bridge_tool_over_floor_loop"),  # a node's cost missing from the run
    ({k: v for k, v in one_tool().items() if k != "phantom_sim"}, FLOOR, "phantom_sim_over_floor_source"),
])
def test_a_missing_role_gives_a_nan_ratio_that_is_not_met(shares, floor, nan):
    figures, met = cost_ratios(shares, floor, SIDES, ["phantom_sim"])
    assert math.isnan(figures[nan]) and met[f"{nan}_max"] is False
    other = ({"physics_bridge_tool_over_floor_loop", "phantom_sim_over_floor_source"} - {nan}).pop()
    assert math.isfinite(figures[other]) and met[f"{other}_max"] is True


def test_cpu_shares_reads_each_processs_share_of_one_core():
    costs = {"liver_physics": {"cpu_share_of_one_core": 0.25, "voluntary_switches_per_s": 900.0},
             "phantom_sim": {"voluntary_switches_per_s": 1000.0}}
    shares = cpu_shares(costs)
    assert shares["liver_physics"] == 0.25 and math.isnan(shares["phantom_sim"])
