"""The benchmark subcommands of ``liver-sim bench``: physics, loop, teleop, topology, segmentation, record (added by
liver_sim.cli.main's COMMANDS). Each handler imports its modules when it runs (liver_sim.cli.main says why);
with --json a benchmark prints one JSON object, else a table, and reports each target as met or not."""
from __future__ import annotations

import json
from pathlib import Path

from liver_sim.cli.arguments import positive_int
from liver_sim.sessions.bag import STORAGES


def add_bench_command(commands) -> None:
    """``liver-sim bench physics [--json]``: step cost of the model (not a test)."""
    parser = commands.add_parser("bench", help="benchmarks (print JSON with --json)")
    kinds = parser.add_subparsers(dest="bench", required=True, metavar="BENCHMARK")
    physics = kinds.add_parser("physics", help="us per step for the default liver and ~10k/~100k-tet livers")
    physics.add_argument("--json", action="store_true", help="print one JSON object")
    physics.add_argument("--sizes", type=positive_int, nargs="*", default=None, metavar="TETS",
                         help="target tet counts of the larger livers (default: 10000 100000)")
    physics.add_argument("--seconds", type=float, default=1.0, help="timing per kernel and mesh (default: 1 s)")
    physics.add_argument("--peers", action="store_true",
                         help="also run each mesh through MuJoCo's flex and report the ratio (pip install .[peers])")
    physics.set_defaults(handler=bench_physics)
    loop = kinds.add_parser("loop", help="the four nodes in closed loop: rates, jitter, latency, Fig. 8 smoothness")
    loop.add_argument("--json", action="store_true", help="print one JSON object")
    loop.add_argument("--duration", type=float, default=30.0, help="seconds of closed loop (default: 30)")
    loop.add_argument("--out", type=Path, default=Path("out/bench_loop"), help="folder for the nodes' logs")
    loop.add_argument("--extra-load", action="store_true",
                      help="then the same run beside one core-bound process at normal priority (with_extra_load)")
    loop.add_argument("--tools", type=int, choices=(1, 2), default=1,
                      help="device sides in closed loop: 1 (default), or 2, each exploring its own spot in its "
                           "namespace (/left, /right)")
    loop.add_argument("--view", action="store_true", help="run the live view (liver-sim view) beside the loop and "
                      "report its CPU share and scene rate (results.view)")
    loop.add_argument("--no-floor", action="store_true",
                      help="skip `bench floor` before the loop: the cost ratios to the floor are None and not judged")
    loop.set_defaults(handler=bench_loop)
    teleop = kinds.add_parser("teleop", help="the closed loop over an emulated teleoperation link: each delay with "
                                             "the local model (passive and direct model updates) and with direct "
                                             "force; stability, passivity by the device's measure, error")
    teleop.add_argument("--json", action="store_true", help="print one JSON object")
    teleop.add_argument("--delays", type=float, nargs="+", default=None, metavar="MS",
                        help="one-way delays (ms; default: 0 10 50 100 200)")
    teleop.add_argument("--jitter", type=float, default=10.0, metavar="MS",
                        help="jitter of every run (ms; default 10, as the target asks)")
    teleop.add_argument("--loss", type=float, default=0.05, metavar="F",
                        help="loss of every run (0-1; default 0.05, as the target asks)")
    teleop.add_argument("--seed", type=int, default=0, help="seed of the jitter and loss")
    teleop.add_argument("--duration", type=float, default=None, help="seconds of closed loop per run (default: 12)")
    teleop.add_argument("--out", type=Path, default=Path("out/bench_teleop"), help="folder for the plots and logs")
    teleop.set_defaults(handler=bench_teleop)
    floor = kinds.add_parser("floor", help="what the 1 kHz hops cost here with no work in them: the floor under the "
                                           "nodes' CPU shares, set by rclpy and Fast DDS")
    floor.add_argument("--json", action="store_true", help="print one JSON object")
    floor.add_argument("--duration", type=float, default=20.0, help="seconds measured (default: 20)")
    floor.add_argument("--out", type=Path, default=Path("out/bench_floor"), help="folder for the processes' logs")
    floor.set_defaults(handler=bench_floor)
    topology = kinds.add_parser("topology", help="time of a tear and of a cut for the default liver and a "
                                                  "~10k-tet liver (target: one 150 Hz frame for the default liver)")
    topology.add_argument("--json", action="store_true", help="print one JSON object")
    topology.add_argument("--sizes", type=positive_int, nargs="*", default=None, metavar="TETS",
                          help="target tet counts of the larger livers (default: 10000)")
    topology.add_argument("--repeats", type=positive_int, default=9, help="timed repetitions (default: 9)")
    topology.set_defaults(handler=bench_topology)
    segmentation = kinds.add_parser("segmentation", help="a CT-sized label volume (512 x 512 x 130) to a ~30k-tet "
                                                         "liver by `liver-sim mesh build`: time and peak memory")
    segmentation.add_argument("--json", action="store_true", help="print one JSON object")
    segmentation.add_argument("--target-tets", type=positive_int, default=30_000, metavar="N",
                              help="tet count aimed at (default: %(default)s)")
    segmentation.add_argument("--out", type=Path, default=Path("out/bench_segmentation"),
                              help="folder for the volume, the mesh and summary.json")
    segmentation.set_defaults(handler=bench_segmentation)
    record = kinds.add_parser("record", help="the closed loop while `liver-sim record` records it: recorder CPU "
                                             "share, haptic loop figures with and without it")
    record.add_argument("--json", action="store_true", help="print one JSON object")
    record.add_argument("--duration", type=float, default=30.0, help="seconds of closed loop per run (default: 30)")
    record.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default: %(default)s)")
    record.add_argument("--out", type=Path, default=Path("out/bench_record"), help="folder for the bag and the logs")
    record.add_argument("--no-compare", action="store_true", help="skip the first run without the recorder")
    record.set_defaults(handler=bench_record)


def bench_physics(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.physics import LARGER_LIVERS, run_physics_bench

    progress = None if args.json else (lambda line: print(line, flush=True))
    sizes = LARGER_LIVERS if args.sizes is None else tuple(args.sizes)
    if args.peers:
        # this command's own modules, loaded when it runs (module docstring)
        from liver_sim.studies.peers import import_mujoco
        try:
            import_mujoco()
        except ImportError as exc:  # liver-sim: error: …, exit status 2, as for any refused option
            raise ValueError(str(exc)) from None
    report = run_physics_bench(sizes, args.seconds, progress, peers=args.peers)
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"machine: {report['machine']['cpu']}, {report['machine']['cores']} cores")
    print(f"{'mesh':<20}{'tets':>8}{'springs':>9}{'us/step 1t':>12}{'us/step all':>12}{'numpy us':>10}"
          f"{'stable dt':>11}{'RT x150Hz':>10}")
    for r in report["results"]:
        print(f"{r['mesh']:<20}{r['tetrahedra']:>8}{r['springs']:>9}{r['us_per_step_1thread']:>12.1f}"
              f"{r['us_per_step_all_threads']:>12.1f}{r['numpy_us_per_step']:>10.0f}"
              f"{r['stable_dt_s'] * 1e6:>9.0f}us{r['realtime_factor_150hz']:>10.2f}")
    print(f"\nwhole frames over a scripted press:\n{'mesh':<20}{'integrator':>18}{'law':>12}{'steps':>7}{'it/step':>9}"
          f"{'ms 1t':>9}{'p99 1t':>9}{'ms all':>9}{'RT 1t':>8}{'RT all':>8}{'error vs ref':>14}")
    for row in (row for r in report["results"] for row in r["integrators"]):
        iterations = "" if row["cg_iterations_per_step"] is None else f"{row['cg_iterations_per_step']:.1f}"
        print(f"{row['mesh']:<20}{row['integrator']:>18}{row['tissue_law']:>12}{row['steps_per_frame']:>7}"
              f"{iterations:>9}{row['ms_per_frame_1thread']:>9.3f}{row['ms_per_frame_p99_1thread']:>9.3f}"
              f"{row['ms_per_frame_all_threads']:>9.3f}"
              f"{row['realtime_factor_1thread']:>8.2f}{row['realtime_factor_all_threads']:>8.2f}"
              f"{row['max_position_error_vs_reference_m'] * 1e3:>12.3f}mm")
    for r in report["results"]:
        print(f"{r['mesh']:<20} peak memory {r['peak_rss_mb']:.0f} MB ({r['peak_rss_mb_per_100k_tets']:.0f} MB per "
              f"100 k tets); the model added {r['model_rss_mb']:.0f} MB ({r['model_rss_mb_per_100k_tets']:.0f} MB per "
              "100 k tets)")
    for r in (r for r in report["results"] if "peer" in r):
        print(f"{r['mesh']:<20} {r['peer']['simulator']}: {r['peer_ms_per_frame']:.2f} ms/frame "
              f"({r['peer']['steps_per_frame']} step, 1 thread, stable: {r['peer']['stable']}), "
              f"peer/liver_sim = {r['peer_ratio']:.2f}"
              + (f", press force peer/liver_sim = {r['peer_force_ratio']:.2f}" if "peer_force_ratio" in r else ""))
    for target, met in report["met"].items():
        print(f"target {target} = {report['targets'][target]:g}: {'met' if met else 'NOT met'}")
    return 0


def bench_topology(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.topology import run_topology_bench

    report = run_topology_bench((10_000,) if args.sizes is None else tuple(args.sizes), args.repeats,
                                None if args.json else (lambda line: print(line, flush=True)))
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"machine: {report['machine']['cpu']}, {report['machine']['cores']} cores")
    print(f"{'mesh':<20}{'tets':>8}{'detect/frame':>14}{'tear':>10}{'faces':>7}{'cut':>10}")
    for r in report["results"]:
        print(f"{r['mesh']:<20}{r['tetrahedra']:>8}{r['tear_detection_per_frame_s'] * 1e3:>12.3f}ms"
              f"{r['tear_s'] * 1e3:>8.1f}ms{r['tear_faces_opened']:>7}{r['cut_s'] * 1e3:>8.1f}ms")
    for target, met in report["met"].items():
        print(f"target {target} = {report['targets'][target]:.4g}: {'met' if met else 'NOT met'}")
    return 0


def bench_segmentation(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.segmentation import run_segmentation_bench

    report = run_segmentation_bench(args.out, args.target_tets, None if args.json else print)
    if args.json:
        print(json.dumps(report))
        return 0
    results, build = report["results"], report["results"]["build"]
    print(f"machine: {report['machine']['cpu']}, {report['machine']['cores']} cores")
    print(f"{' x '.join(map(str, results['voxels']))} voxels -> {build['tetrahedra']} tets in "
          f"{results['seconds']:.1f} s, "
          f"peak memory {results['peak_memory_mb']:.0f} MB; surface within {build['max_surface_distance_mm']:.2f} mm "
          f"({build['max_surface_distance_voxels']:.2f} voxels) of the label; {args.out / 'summary.json'}")
    for target, met in report["met"].items():
        print(f"target {target} = {report['targets'][target]:g}: {'met' if met else 'NOT met'}")
    return 0


def bench_loop(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.loop import FLOOR_DURATION_S, run_loop_bench

    report = run_loop_bench(args.duration, args.out / "logs", None if args.json else print,
                            extra_load=args.extra_load, view=args.view, tools=args.tools,
                            floor_duration_s=None if args.no_floor else FLOOR_DURATION_S)
    if args.json:
        print(json.dumps(report, default=float))
        return 0
    print(json.dumps(report["results"], indent=2, default=float))
    for line in cost_lines(report):
        print(line)
    for target, met in report["met"].items():
        print(f"target {target} = {target_value(report['targets'], target)}: {'met' if met else 'NOT met'}")
    return 0


def target_value(targets: dict, name: str):
    """The bound of `met` entry `name` among a loop report's `targets`: its own key; the key it ends with (a device
    side's, 'left_haptic_rate_hz_min'); a neighbour's under `neighbour` ('neighbour_' prefixed); a simulated PHANToM's
    ratio ('phantom_sim_left_over_floor_source_max'); else 'see targets'."""
    if name in targets:
        return targets[name]
    known = next((key for key in targets if name.endswith(key)), None)
    if known is not None:
        return targets[known]
    if name.startswith("neighbour_") and name[len("neighbour_"):] in targets.get("neighbour", {}):
        return targets["neighbour"][name[len("neighbour_"):]]
    if name.startswith("phantom_sim") and name.endswith("_over_floor_source_max"):
        return targets.get("phantom_sim_over_floor_source_max", "see targets")
    return "see targets"


def cost_lines(report: dict) -> list[str]:
    """The lines `bench loop` prints of what its processes cost: the floor's shares of a core, then each cost
    ratio to the floor beside the absolute share it was taken from."""
    results, floor = report["results"], report["floor"]
    if floor is None:
        return ["cost against the floor: not measured (--no-floor)"]
    lines = [f"the floor ({floor['duration_s']:g} s just before): "
             + ", ".join(f"{role} {cost['cpu_share_of_one_core']:.3f}" for role, cost in floor["processes"].items())
             + " of a core",
             f"physics, bridges and tool nodes: {results['physics_bridge_tool_cores']:.3f} of a core, "
             f"{results['physics_bridge_tool_over_floor_loop']:.2f}x the floor's loop per tool"]
    for key in (key for key in results if key.endswith("_over_floor_source")):
        label = key.removesuffix("_over_floor_source")
        lines.append(f"{label}: {results[f'{label}_cores']:.3f} of a core, {results[key]:.2f}x the floor's source")
    return lines


def bench_teleop(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.teleop import TELEOP_DELAYS_MS, TELEOP_RUN_S, run_teleop_bench

    for option, value, low, high in (("--jitter", args.jitter, 0.0, 1000.0), ("--loss", args.loss, 0.0, 1.0)):
        if not low <= value <= high:
            raise ValueError(f"{option} must lie in [{low:g}, {high:g}], got {value:g}")
    delays = TELEOP_DELAYS_MS if args.delays is None else tuple(args.delays)
    if any(not 0.0 <= d <= 1000.0 for d in delays):
        raise ValueError(f"--delays must lie in [0, 1000] ms, got {list(delays)}")
    report = run_teleop_bench(delays, args.jitter, args.loss, args.out, None if args.json else print,
                              args.duration or TELEOP_RUN_S, args.seed)
    if args.json:
        print(json.dumps(report, default=float))
        return 0
    print(f"{'variant':<22}{'delay ms':>9}{'stable':>8}{'passive':>8}{'generated mJ':>13}{'to hand mJ':>11}"
          f"{'bridge mJ':>10}{'peak N':>8}{'error N':>9}{'depth mm':>9}")
    for r in report["rows"]:
        print(f"{r['variant']:<22}{r['delay_ms']:>9g}{str(r['stable']):>8}"
              f"{str(r['passive']):>8}{r['energy_generated_max_j'] * 1e3:>13.3f}{r['energy_to_hand_j'] * 1e3:>11.2f}"
              f"{r['bridge_energy_to_hand_j'] * 1e3:>10.2f}{r['peak_force_n']:>8.2f}{r['force_error_rms_n']:>9.3f}"
              f"{r['penetration_max_mm']:>9.1f}")
    print(f"first unstable delay (ms): {report['first_unstable_delay_ms']}; plots: {', '.join(report['plots'])}")
    for target, met in report["met"].items():
        print(f"target {target} = {report['targets'][target]:g} (jitter {report['targets']['with_jitter_ms']:g} ms, "
              f"loss {report['targets']['with_loss']:g}): {'met' if met else 'NOT met'}")
    return 0


def bench_floor(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.floor import run_floor_bench

    report = run_floor_bench(args.duration, args.out / "logs", None if args.json else print)
    if args.json:
        print(json.dumps(report, default=float))
        return 0
    for role, cost in report["processes"].items():
        print(f"{role:<8} {cost['cpu_share_of_one_core']:.3f} of a core, {cost['voluntary_switches_per_s']:.0f} "
              "voluntary switches/s")
    print(report["reading"])
    return 0


def bench_record(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.bench.record import run_record_bench

    report = run_record_bench(args.duration, args.out, args.storage,
                              None if args.json else (lambda line: print(line, flush=True)),
                              compare=not args.no_compare)
    if args.json:
        print(json.dumps(report, default=float))
        return 0
    print(json.dumps({k: report[k] for k in ("recorder", "bag")}, indent=2, default=float))
    number = lambda value: float("nan") if value is None else value  # noqa: E731
    without = report.get("loop_without_recorder", {})
    print(f"{'haptic loop':<28}{'without recorder':>18}{'with recorder':>16}")
    for name, value in report["loop_with_recorder"].items():
        print(f"{name:<28}{number(without.get(name)):>18.4g}{number(value):>16.4g}")
    for target, met in report["met"].items():
        before = report.get("met_without_recorder", {}).get(target)
        bound = target_value(report["targets"], target)
        print(f"target {target} = {bound}: {'met' if met else 'NOT met'} while recording"
              + ("" if before is None else f" ({'met' if before else 'NOT met'} without)"))
    return 0
