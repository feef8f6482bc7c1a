"""`liver-sim bench record`: the loop benchmark (liver_sim.bench.loop.run_loop_bench) with `liver-sim record`
recording the whole network, reporting the recorder's CPU share and whether the loop targets still hold."""
from __future__ import annotations

from pathlib import Path

from liver_sim.bench.loop import run_loop_bench
from liver_sim.sessions.bag import bag_info, check_bag
from liver_sim.sessions.record import recorder_command


def new_path(path: Path) -> Path:
    """`path`, or the first of path_2, path_3, … that does not exist."""
    candidate, k = path, 1
    while candidate.exists():
        k += 1
        candidate = path.with_name(f"{path.name}_{k}")
    return candidate


def loop_figures(report: dict) -> dict:
    """The haptic loop's headline figures of a run_loop_bench report."""
    results = report["results"]
    loops = results["node_loops"]
    bridge, physics = loops.get("haptic_bridge: loop", {}), loops.get("liver_physics: loop", {})
    return {"haptic_rate_hz": float(bridge.get("rate_hz", 0.0)),
            "haptic_period_error_p99_s": float(bridge.get("jitter_p99_s", "nan")),
            "haptic_max_gap_on_wire_s": results["haptic_on_wire"]["max_gap_s"],
            "pose_to_force_p99_s": results["pose_to_force_p99_s"],
            "physics_rate_hz": float(physics.get("rate_hz", 0.0)),
            "fig8_smoothness_ratio": results["fig8_smoothness_ratio"]}


def run_record_bench(duration_s: float = 30.0, out: Path = Path("out/bench_record"), storage: str = "mcap",
                     progress=None, compare: bool = True) -> dict:
    """run_loop_bench, without its floor (no cost ratios), with a recorder into a new bag out/bench_session (or
    out/bench_session_2, … : nothing there is replaced) — and first without it when `compare` — adding the
    recorder's CPU share (CPU seconds per wall second, of one core and of the machine, from its rclpy start-up to
    the closed bag; imports excluded), the bag's counts and rates, and the loop figures side by side."""
    say = progress or (lambda line: None)
    without = None
    if compare:
        say("the closed loop without the recorder:")
        without = run_loop_bench(duration_s, out / "logs_without_recorder", progress, floor_duration_s=None)
    bag = new_path(out / "bench_session")
    say("the closed loop with the recorder:")
    report = run_loop_bench(duration_s, out / "logs", progress, {"recorder": recorder_command(bag, storage)},
                            floor_duration_s=None)
    report["benchmark"] = "record"
    info = bag_info(bag)
    counts = check_bag(bag)
    cpu_s, wall_s = float(info.custom_data["recorder_cpu_s"]), float(info.custom_data["recorder_wall_s"])
    cores = report["machine"]["cores"] or 1
    report["recorder"] = {"cpu_s": cpu_s, "wall_s": wall_s, "cpu_share_of_one_core": cpu_s / wall_s,
                          "cpu_share_of_machine": cpu_s / wall_s / cores,
                          "max_backlog": int(info.custom_data["recorder_max_backlog"]),
                          "history_depth": int(info.custom_data["recorder_history_depth"]),
                          "lost_messages": int(info.custom_data["lost_messages"]), "storage": storage}
    seconds = info.duration_ns * 1e-9
    report["bag"] = {"path": str(bag), "duration_s": seconds, "messages": counts,
                     "rate_hz": {t: n / seconds for t, n in counts.items()} if seconds > 0 else {},
                     "bytes": sum(f.stat().st_size for f in bag.iterdir())}
    report["loop_with_recorder"] = loop_figures(report)
    if without is not None:
        report["loop_without_recorder"] = loop_figures(without)
        report["met_without_recorder"] = without["met"]
    return report
