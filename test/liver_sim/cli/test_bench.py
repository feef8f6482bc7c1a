"""`liver-sim bench loop`'s floor: `--no-floor` reaches the benchmark, and the table prints the floor's shares and
each cost ratio beside its share (the benchmark itself replaced by its report: no ROS here)."""
import pytest

import liver_sim.bench.loop as loop_bench
from liver_sim.bench.loop import COST_TARGETS, FLOOR_DURATION_S, cost_ratios
from liver_sim.cli.main import build_parser

SHARES = {"liver_physics": 0.25, "haptic_bridge": 0.125, "liver_tool": 0.125, "phantom_sim": 0.5}
FLOOR = {"source": {"cpu_share_of_one_core": 0.25}, "relay": {"cpu_share_of_one_core": 0.0625},
         "loop": {"cpu_share_of_one_core": 0.25}}


@pytest.fixture
def asked(monkeypatch):
    """The keyword arguments each run_loop_bench was called with; it returns the report of SHARES and FLOOR, or of
    SHARES alone when the floor is skipped."""
    calls = []

    def fake(duration_s, log_dir, progress, **options):
        calls.append(options)
        floor = options["floor_duration_s"]
        shares = None if floor is None else {role: cost["cpu_share_of_one_core"] for role, cost in FLOOR.items()}
        figures, met = cost_ratios(SHARES, shares, ["haptic_bridge", "liver_tool"], ["phantom_sim"])
        return {"results": figures, "met": met, "targets": dict(COST_TARGETS),
                "floor": None if floor is None else {"duration_s": floor, "processes": FLOOR}}

    monkeypatch.setattr(loop_bench, "run_loop_bench", fake)
    return calls


def run(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    return args.handler(args)


def test_bench_loop_runs_the_floor_first_by_default_and_prints_the_ratios(asked, capsys):
    assert run(["bench", "loop", "--duration", "3"]) == 0
    assert asked[0]["floor_duration_s"] == FLOOR_DURATION_S
    out = capsys.readouterr().out
    assert f"the floor ({FLOOR_DURATION_S:g} s just before): source 0.250, relay 0.062, loop 0.250 of a core" in out
    assert "physics, bridges and tool nodes: 0.500 of a core, 2.00x the floor's loop per tool" in out
    assert "phantom_sim: 0.500 of a core, 2.00x the floor's source" in out
    assert "target physics_bridge_tool_over_floor_loop_max = 4.0: met" in out
    assert "target phantom_sim_over_floor_source_max = 1.3: NOT met" in out


def test_bench_loop_no_floor_skips_it_and_judges_no_cost(asked, capsys):
    assert run(["bench", "loop", "--no-floor"]) == 0
    assert asked[0]["floor_duration_s"] is None
    out = capsys.readouterr().out
    assert "cost against the floor: not measured (--no-floor)" in out
    assert '"physics_bridge_tool_over_floor_loop": null' in out and "target" not in out


def test_no_floor_is_off_unless_asked():
    assert build_parser().parse_args(["bench", "loop"]).no_floor is False
    assert build_parser().parse_args(["bench", "loop", "--no-floor"]).no_floor is True


def test_each_met_entry_of_a_loop_report_finds_its_bound():
    from liver_sim.bench.loop import LOOP_TARGETS, NEIGHBOUR_TARGETS
    from liver_sim.cli.bench import target_value

    targets = {**LOOP_TARGETS, **COST_TARGETS, "neighbour": NEIGHBOUR_TARGETS}
    assert target_value(targets, "haptic_rate_hz_min") == LOOP_TARGETS["haptic_rate_hz_min"]
    assert target_value(targets, "left_haptic_rate_hz_min") == LOOP_TARGETS["haptic_rate_hz_min"]
    assert (target_value(targets, "neighbour_pose_to_command_at_client_p99_s_max")
            == NEIGHBOUR_TARGETS["pose_to_command_at_client_p99_s_max"])
    assert (target_value(targets, "phantom_sim_left_over_floor_source_max")
            == COST_TARGETS["phantom_sim_over_floor_source_max"])
    assert target_value(targets, "unknown") == "see targets"
