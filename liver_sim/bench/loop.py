"""`liver-sim bench loop`: the four nodes in closed loop (R4 of docs/paper.md), or the physics and two device sides
(`--tools 2`), watched from outside as a rig would: rates and period errors on the wire, pose-to-force latency per
device, the Fig. 8 smoothness ratio, the physics frame's compute, each against its target, beside the machine's own
stalls; and what each process cost against the bare 1 kHz hops of `bench floor` run just before it."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from liver_sim.base.process_settings import cli_command_line
from liver_sim.bench.floor import run_floor_bench
from liver_sim.bench.machine import machine
from liver_sim.bench.physics import contact_frame_times
from liver_sim.mesh.landmarks import upper_skin_point
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.running.machine_stalls import stall_summary
from liver_sim.running.network import ROOT_LABEL, closed_loop_plan, run_network, wire_gaps, wire_rates
from liver_sim.sessions.analysis import contact_fraction, fig8_figures, held_wrench_baseline
from liver_sim.sessions.parameters import node_parameters

LOOP_TARGETS = {"physics_rate_hz": (147.0, 153.0), "haptic_rate_hz_min": 995.0, "haptic_period_error_p99_s_max": 0.0005,
                "haptic_max_gap_s_max": 0.005, "haptic_max_gap_outside_machine_stalls_s_max": 0.005,
                "pose_to_force_p99_s_max": 0.002, "pose_to_force_p99_outside_machine_stalls_s_max": 0.002,
                "fig8_smoothness_ratio_min": 5.0, "fig8_smoothness_ratio_outside_machine_stalls_min": 5.0}
#: What a neighbour on the rig must see (docs/contract.md): an independent client at normal priority (the listener:
#: this process) counts the frames and commands by their header stamps and times each command from the stamp of
#: the device sample it was computed from to its own reception.
NEIGHBOUR_TARGETS = {"frames_hz_by_stamp_min": 148.0, "commands_hz_by_stamp_min": 995.0,
                     "pose_to_command_at_client_p99_s_max": 0.0025, "command_gap_at_client_max_s_max": 0.010}
#: What the network may cost, as ratios of shares of one core (`processes`) to those of `bench floor`'s matching
#: roles measured in the same invocation (:func:`cost_ratios`): the physics, the bridges and the tool nodes together
#: over the floor's `loop` once per tool, and each simulated PHANToM, which stands in for a device's own driver,
#: over the floor's `source`.
COST_TARGETS = {"physics_bridge_tool_over_floor_loop_max": 4.0, "phantom_sim_over_floor_source_max": 1.3}
#: Seconds `bench loop` measures the floor for before the loop.
FLOOR_DURATION_S = 20.0
#: After a machine stall the simulated hand has moved on by the stall's length and the physics catches up two
#: frames: commands from a stall's start to this long (s, three physics frames) after its end are the stall's.
MACHINE_STALL_SETTLE_S = 0.02


#: Fig. 8 compares commands sent one tick apart: pairs further apart than this (s) are scheduling gaps.
FIG8_MAX_PERIOD_S = 0.0015


#: `bench loop --tools 2`: where each hand explores the default liver (x, y m of the upper skin): the dome and the
#: left lobe, 7.6 cm apart.
HAND_SPOTS_XY = {"left": (-0.046, 0.004), "right": (0.03, 0.0)}


def run_loop_bench(duration_s: float = 30.0, log_dir=None, progress=None, observers: dict | None = None,
                   extra_load: bool = False, view: bool = False, check_domain: bool = True, tools: int = 1,
                   floor_duration_s: float | None = FLOOR_DURATION_S) -> dict:
    """The loop benchmark's JSON object (:func:`loop_run`), after `bench floor` (liver_sim.bench.floor) has run for
    `floor_duration_s` with its logs beside the loop's: its processes' costs under `floor` (None when
    `floor_duration_s` is None: no floor, no cost ratios). With `extra_load`, the same run follows with one
    core-bound process at normal priority beside the network, reported under `with_extra_load` (its cost ratios
    against the same floor); with `view`, the live view (`liver-sim view`) runs beside the network, its figures under
    `results.view`. `check_domain`: before each run (network.run_network). `tools` 2: two device sides, each
    exploring its own spot (HAND_SPOTS_XY)."""

    log_dir = Path(log_dir or "out/bench_loop/logs")
    say = progress or (lambda line: None)
    floor = floor_shares = None
    if floor_duration_s is not None:
        say(f"the floor first, the bare 1 kHz hops of `bench floor` for {floor_duration_s:g} s:")
        measured = run_floor_bench(floor_duration_s, log_dir.with_name(log_dir.name + "_floor"), progress)
        floor = {"duration_s": measured["duration_s"], "processes": measured["processes"]}
        floor_shares = cpu_shares(floor["processes"])
    report = loop_run(duration_s, log_dir, progress, observers, view=view, check_domain=check_domain, tools=tools,
                      floor_shares=floor_shares)
    report["floor"] = floor
    if view:
        report["results"]["view"] = view_figures(report["processes"], log_dir / VIEW_SUMMARY)
    if extra_load:
        say("the same run with one core-bound process at normal priority beside it:")
        loaded = loop_run(duration_s, log_dir.with_name(log_dir.name + "_extra_load"), progress, observers, 1,
                          check_domain=check_domain, tools=tools, floor_shares=floor_shares)
        report["with_extra_load"] = {key: loaded[key] for key in ("results", "processes", "cores_used",
                                                                   "load_average", "met")}
    return report


def bench_plan(tools: int):
    """The closed loop of the benchmark: the simulated hand explores the dome, looped; with `tools` 2 one hand per
    spot of HAND_SPOTS_XY, each in its namespace."""
    explore = {"loop_script": True, "script": "explore"}
    if tools == 1:
        return closed_loop_plan(extra={"phantom_sim": explore})
    if tools != 2:
        raise ValueError(f"--tools must be 1 or 2, got {tools}")
    mesh = default_liver()
    return closed_loop_plan(extra={"phantom_sim": explore}, tools={
        name: {"phantom_sim": {"anchor_m": [round(float(v), 6) for v in upper_skin_point(mesh, xy)]}}
        for name, xy in HAND_SPOTS_XY.items()})


def device_figures(run, label: str) -> tuple[dict, dict]:
    """(figures, met) of one device side of the run: its commands' rates and gaps on the wire, the device sample →
    command latency, the Fig. 8 smoothness ratio against its offline baseline, each also away from machine stalls,
    and what the listener saw as a neighbour (:func:`neighbour_figures`)."""
    start, end = run.window_s
    sent = run.force_published_s[label]
    inside = (sent >= start) & (sent <= end)
    sent_local = sent[inside]
    force = run.forces[label][1][inside]
    latency = run.pose_to_force_s[label][inside]
    stalls = run.machine_stalls
    calm = np.ones(sent_local.size, dtype=bool)  # commands away from every machine stall
    for stall_start, stall_end in stalls:
        calm &= (sent_local < stall_start) | (sent_local > stall_end + MACHINE_STALL_SETTLE_S)
    latency_calm = latency[calm & np.isfinite(latency)]
    latency = latency[np.isfinite(latency)]
    baseline = held_wrench_baseline(sent_local, run.wrench_arrival_s[label], run.wrench_n[label],
                                    run.device_arrival_s[label], node_parameters(())["haptic_bridge"])
    fig8 = fig8_figures(force, baseline, sent_local, FIG8_MAX_PERIOD_S)
    fig8_calm = fig8_figures(force[calm], baseline[calm], sent_local[calm], FIG8_MAX_PERIOD_S)
    gaps = wire_gaps(run, LOOP_TARGETS["haptic_max_gap_s_max"], label)
    short = np.diff(sent_local)
    short = short[short <= LOOP_TARGETS["haptic_max_gap_s_max"]]
    figures = {
        "haptic_on_wire": wire_rates(run, label)["haptic"],
        "pose_to_force_p50_s": float(np.percentile(latency, 50)) if latency.size else None,
        "pose_to_force_p99_s": float(np.percentile(latency, 99)) if latency.size else None,
        "pose_to_force_p99_outside_machine_stalls_s": (float(np.percentile(latency_calm, 99)) if latency_calm.size
                                                       else None),
        "contact_fraction": contact_fraction(force),
        **{key: value for key, value in fig8.items() if key.startswith("largest_jump")},
        "fig8_script": "explore",
        "fig8_baseline": "offline: BridgeTick(local_model none) at the live bridge's tick times",
        "fig8_smoothness_ratio": fig8["smoothness_ratio"],
        "fig8_smoothness_ratio_steady": fig8["smoothness_ratio_steady"],
        "fig8_smoothness_ratio_outside_machine_stalls": fig8_calm["smoothness_ratio"],
        "commands_outside_machine_stalls": float(calm.mean()) if calm.size else 1.0,
        "haptic_gaps_over_target": gaps,
        "haptic_max_gap_outside_machine_stalls_s": max([float(short.max(initial=0.0))]
                                                       + [gap["product_s"] for gap in gaps]),
    }
    haptic, t = figures["haptic_on_wire"], LOOP_TARGETS
    met = {
        "haptic_rate_hz_min": haptic["rate_hz"] >= t["haptic_rate_hz_min"],
        "haptic_period_error_p99_s_max": (haptic["period_error_p99_s"] or 1.0) <= t["haptic_period_error_p99_s_max"],
        "haptic_max_gap_s_max": (haptic["max_gap_s"] or 1.0) <= t["haptic_max_gap_s_max"],
        "haptic_max_gap_outside_machine_stalls_s_max": (figures["haptic_max_gap_outside_machine_stalls_s"]
                                                        <= t["haptic_max_gap_outside_machine_stalls_s_max"]),
        "pose_to_force_p99_s_max": (figures["pose_to_force_p99_s"] or 1.0) <= t["pose_to_force_p99_s_max"],
        "fig8_smoothness_ratio_min": (figures["fig8_smoothness_ratio"] or 0.0) >= t["fig8_smoothness_ratio_min"],
        "pose_to_force_p99_outside_machine_stalls_s_max": (
            (figures["pose_to_force_p99_outside_machine_stalls_s"] or 1.0)
            <= t["pose_to_force_p99_outside_machine_stalls_s_max"]),
        "fig8_smoothness_ratio_outside_machine_stalls_min": (
            (figures["fig8_smoothness_ratio_outside_machine_stalls"] or 0.0)
            >= t["fig8_smoothness_ratio_outside_machine_stalls_min"]),
    }
    neighbour = neighbour_figures(run, label)
    met.update({f"neighbour_{key}": value for key, value in neighbour.pop("met").items()})
    figures["neighbour"] = neighbour
    return figures, met


def cpu_shares(costs: dict) -> dict:
    """label -> share of one core, of network.process_costs' `costs`."""
    return {label: cost.get("cpu_share_of_one_core", float("nan")) for label, cost in costs.items()}


def cost_ratios(shares: dict, floor_shares: dict | None, sides: list, devices: list) -> tuple[dict, dict]:
    """(figures, met) of what the run's processes cost against the floor's matching roles (COST_TARGETS).

    `shares` and `floor_shares` map label to share of one core (:func:`cpu_shares`) of the run and of `bench floor`
    in the same invocation; `sides` are the labels of the bridges and tool nodes, `devices` those of the simulated
    PHANToMs, one per tool (NetworkPlan.after_physics). Figures: the absolute shares `physics_bridge_tool_cores`
    and `{device}_cores`, beside `physics_bridge_tool_over_floor_loop`, their sum over the floor's `loop` once per
    device, and `{device}_over_floor_source`, each PHANToM's over the floor's `source`. With no floor
    (`floor_shares` None) the ratios are None and `met` has no entry for them; a role missing from either run, or a
    floor share not above zero, gives a NaN ratio, not met."""

    def share(label):
        return shares.get(label, float("nan"))

    def over(value, role):
        floor_share = floor_shares.get(role, float("nan"))
        return value / floor_share if floor_share > 0.0 else float("nan")

    figures = {"physics_bridge_tool_cores": sum(share(label) for label in ["liver_physics", *sides])}
    figures.update({f"{label}_cores": share(label) for label in devices})
    if floor_shares is None:
        figures["physics_bridge_tool_over_floor_loop"] = None
        figures.update({f"{label}_over_floor_source": None for label in devices})
        return figures, {}
    figures["physics_bridge_tool_over_floor_loop"] = over(figures["physics_bridge_tool_cores"] / len(devices), "loop")
    figures.update({f"{label}_over_floor_source": over(share(label), "source") for label in devices})
    met = {"physics_bridge_tool_over_floor_loop_max": (figures["physics_bridge_tool_over_floor_loop"]
                                                       <= COST_TARGETS["physics_bridge_tool_over_floor_loop_max"])}
    met.update({f"{label}_over_floor_source_max": (figures[f"{label}_over_floor_source"]
                                                   <= COST_TARGETS["phantom_sim_over_floor_source_max"])
                for label in devices})
    return figures, met


def loop_run(duration_s: float, log_dir, progress=None, observers: dict | None = None, extra_load: int = 0,
             view: bool = False, check_domain: bool = True, tools: int = 1, floor_shares: dict | None = None) -> dict:
    """One run of the physics and `tools` device sides in closed loop for `duration_s` (R4), watched by a listener
    as a rig would.

    Rates and period errors are given twice: as each node's own loop measured them (diagnostics)
    and as the messages went on the wire (DDS publication times), over the `duration_s` in which all
    nodes ran.  Per device side (:func:`device_figures`; with two tools under `devices`, by tool): the
    pose-to-force latency, from the publication of a device sample on /phantom/measured_cp to that of the force
    command computed from it, and the Fig. 8 baseline (local_model none), the node's BridgeTick run offline at the
    live bridge's tick times on the physics wrenches and device samples the listener received
    (analysis.held_wrench_baseline): no second live bridge.  `physics_frame_compute_p99_s` is the physics' own
    measure of a frame's compute (diagnostics).  `processes` gives what each process cost over the window
    (network.process_costs: share of one core, context switches per second), judged against `floor_shares`, the
    floor's (:func:`cost_ratios`; None: not judged), `load_average` the machine's before and after.  `observers`
    (label -> argv) run beside the network (NetworkPlan.observers), e.g. a recorder; `extra_load` core-bound
    processes at normal priority beside it (network.run_network); `view`: the live view too (its cost in
    `processes`).

    Sentinels (liver_sim.running.machine_stalls, started by run_network) note when the machine itself ran nothing that
    was due; each command gap over the target is listed with the part of it the machine
    stalled (`haptic_gaps_over_target`), and the largest gap without those parts is a figure of its own, as
    are the latency and Fig. 8 over the commands away from the stalls (from a stall's start to
    MACHINE_STALL_SETTLE_S after its end: the simulated hand moved on meanwhile).
    """

    plan = bench_plan(tools)
    plan.observers.update(observers or {})
    if view:  # the live view joins as a viewer would, beside the four nodes
        names = [label for label in plan.namespaces if label != ROOT_LABEL]
        plan.commands[VIEW] = cli_command_line("view", "--port", "0", "--summary", str(log_dir / VIEW_SUMMARY),
                                               *(["--tools", *names] if names else []))
    load_before = os.getloadavg()
    run = run_network(plan, duration_s, log_dir, progress or (lambda line: None), extra_load=extra_load,
                      check_domain=check_domain)
    load_after = os.getloadavg()
    physics = run.diagnostics.get("liver_physics: loop", {})
    figures = {"physics_on_wire": wire_rates(run, next(iter(plan.namespaces)))["physics"],
               "physics_frame_compute_p99_s": float(physics.get("frame_compute_p99_s", "nan")),
               "node_loops": run.diagnostics, "machine_stalls": stall_summary(run.machine_stalls)}
    met = {"physics_rate_hz": (LOOP_TARGETS["physics_rate_hz"][0] <= figures["physics_on_wire"]["rate_hz"]
                               <= LOOP_TARGETS["physics_rate_hz"][1])}
    if tools == 1:
        device, device_met = device_figures(run, ROOT_LABEL)
        figures.update(device)
        met.update(device_met)
    else:
        figures["devices"] = {}
        for label in plan.namespaces:
            figures["devices"][label], device_met = device_figures(run, label)
            met.update({f"{label}_{key}": value for key, value in device_met.items()})
        figures["physics_frame_offline"] = contact_frame_times(
            [upper_skin_point(default_liver(), xy) for xy in HAND_SPOTS_XY.values()])
    costs = run.process_costs
    sides = [label for label in plan.commands if label.startswith(("haptic_bridge", "liver_tool"))]
    cost, cost_met = cost_ratios(cpu_shares(costs), floor_shares, sides, list(plan.after_physics))
    figures.update(cost)
    met.update(cost_met)
    return {"benchmark": "loop", "machine": machine(), "duration_s": duration_s, "tools": tools,
            "results": figures, "processes": costs,
            "cores_used": sum(c["cpu_share_of_one_core"] for c in costs.values()),
            "load_average": {"before": list(load_before), "after": list(load_after)},
            "targets": {**LOOP_TARGETS, **COST_TARGETS, "neighbour": NEIGHBOUR_TARGETS}, "met": met}


#: The live view's label among the processes of a run, and the file (in the run's log folder) of its summary.
VIEW = "view"
VIEW_SUMMARY = "view_summary.json"


def view_figures(costs: dict, summary: Path) -> dict:
    """The live view beside the loop: its share of a core and the scenes per second of the summary it wrote at
    exit (`liver-sim view --summary`; None when it wrote none)."""
    try:
        rate = json.loads(summary.read_text())["scenes_per_s"]
    except (OSError, ValueError, KeyError):
        rate = None
    return {"cpu_share_of_one_core": costs.get(VIEW, {}).get("cpu_share_of_one_core"), "scenes_per_s": rate}


def neighbour_figures(run, label: str = ROOT_LABEL) -> dict:
    """What the listener, a client at normal priority beside the nodes, saw within the run's window of device side
    `label`: frames and commands per second counted by their header stamps (ROS time), from each command's stamp
    (its device sample's) to its reception here (p50, p99), and the longest wait between two commands' receptions;
    `met` against NEIGHBOUR_TARGETS."""
    wall_minus_monotonic = time.time() - time.monotonic()
    start, end = (t + wall_minus_monotonic for t in run.window_s)
    frames = run.nodes_stamp_s[(run.nodes_stamp_s >= start) & (run.nodes_stamp_s <= end)]
    stamps = run.force_stamp_s[label]
    inside = (stamps >= start) & (stamps <= end)
    latency = run.stamp_to_arrival_s[label][inside]
    arrivals = np.sort(run.forces[label][0])
    arrivals = arrivals[(arrivals >= run.window_s[0]) & (arrivals <= run.window_s[1])]
    figures = {"client": "the listener (this process, normal priority): /liver/nodes, /liver/surface, "
                         "/liver/tool_wrench, /phantom/measured_cp, /phantom/servo_cf, /diagnostics",
               "frames_hz_by_stamp": frames.size / (end - start),
               "commands_hz_by_stamp": int(inside.sum()) / (end - start),
               "pose_to_command_at_client_p50_s": float(np.percentile(latency, 50)) if latency.size else None,
               "pose_to_command_at_client_p99_s": float(np.percentile(latency, 99)) if latency.size else None,
               "command_gap_at_client_max_s": float(np.diff(arrivals).max()) if arrivals.size > 1 else None}
    t = NEIGHBOUR_TARGETS
    figures["met"] = {
        "frames_hz_by_stamp_min": figures["frames_hz_by_stamp"] >= t["frames_hz_by_stamp_min"],
        "commands_hz_by_stamp_min": figures["commands_hz_by_stamp"] >= t["commands_hz_by_stamp_min"],
        "pose_to_command_at_client_p99_s_max": ((figures["pose_to_command_at_client_p99_s"] or 1.0)
                                                <= t["pose_to_command_at_client_p99_s_max"]),
        "command_gap_at_client_max_s_max": ((figures["command_gap_at_client_max_s"] or 1.0)
                                            <= t["command_gap_at_client_max_s_max"])}
    return figures
