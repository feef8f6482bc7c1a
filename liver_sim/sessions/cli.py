"""The session subcommands of ``liver-sim``: record, replay, resimulate, report (listed in cli.COMMANDS)."""
from __future__ import annotations

import json
from pathlib import Path

from liver_sim.sessions.bag import STORAGES


def _progress(line: str) -> None:
    print(line, flush=True)


def _output(args, suffix: str) -> Path:
    """--out, or a folder beside BAG named BAG<suffix>."""
    return args.out or args.bag.with_name(args.bag.name + suffix)


def add_record_command(commands) -> None:
    """``liver-sim record [--topics …] [--storage mcap|sqlite3] [--out DIR] [--duration S] [--marker]``."""
    parser = commands.add_parser("record", help="record the product's topics into a rosbag2 bag until Ctrl-C")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC",
                        help="topics to record (default: every topic of docs/contract.md but /liver/marker, and the "
                             "Fig. 8 baseline force)")
    parser.add_argument("--marker", action="store_true", help="also record /liver/marker (30 Hz skin triangles)")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None,
                        help="bag folder to create (default: out/sessions/session_<date>_<time>)")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds (default: on Ctrl-C)")
    parser.set_defaults(handler=record)


def record(args) -> int:
    import time

    from liver_sim.sessions.record import EXIT_LOST, default_topics, run_record

    out = args.out or Path("out/sessions") / time.strftime("session_%Y%m%d_%H%M%S")
    topics = args.topics or default_topics(marker=args.marker)
    if args.marker and args.topics and "/liver/marker" not in topics:
        topics.append("/liver/marker")
    _, failed = run_record(out, topics, args.storage, args.duration, _progress)
    return EXIT_LOST if failed else 0


def add_replay_command(commands) -> None:
    """``liver-sim replay BAG [--rate R] [--topics …] [--delay S] [--remap-device-commands TOPIC]``."""
    parser = commands.add_parser("replay", help="republish a bag's topics with their original timing")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default: 1)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics (default: all in the bag); "
                        "e.g. /phantom/measured_cp to drive liver_tool with a past session's device")
    parser.add_argument("--delay", type=float, default=1.0,
                        help="seconds to wait for subscribers before the first message (default: 1)")
    parser.add_argument("--remap-device-commands", metavar="TOPIC", default=None,
                        help="replay the recorded device commands (/phantom/servo_cf…) on TOPIC; without it they "
                             "are never replayed, so that no device is driven by a recording")
    parser.set_defaults(handler=replay)


def replay(args) -> int:
    from liver_sim.sessions.replay import run_replay

    run_replay(args.bag, args.rate, args.topics, args.delay, _progress, args.remap_device_commands)
    return 0


def add_resimulate_command(commands) -> None:
    """``liver-sim resimulate BAG [-p name:=value …] [--out BAG2] [--storage …] [--compare]``."""
    parser = commands.add_parser("resimulate", help="re-run physics and haptic bridge offline on a bag's tool poses")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder holding /tool/pose")
    parser.add_argument("-p", dest="overrides", action="append", default=[], metavar="NAME:=VALUE",
                        help="a liver_physics or haptic_bridge parameter (prefix liver_physics. or haptic_bridge. "
                             "to set only one node's); repeatable")
    parser.add_argument("--out", type=Path, default=None, help="output bag folder (default: BAG_resimulated)")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="output storage (default: %(default)s)")
    parser.add_argument("--compare", action="store_true", help="also render the force without local model (the "
                        "physics force held, Fig. 8) on /phantom/servo_cf_without_local_model")
    parser.set_defaults(handler=resimulate)


def resimulate(args) -> int:
    from liver_sim.sessions.resimulate import resimulate as run

    run(args.bag, _output(args, "_resimulated"), args.overrides, args.storage, _progress, args.compare)
    return 0


def add_fig8_command(commands) -> None:
    """``liver-sim fig8 [-p name:=value …] [--out DIR] [--json]``."""
    parser = commands.add_parser("fig8", help="Fig. 8 offline: the explore script's force with and without the "
                                              "local model, largest change between 1 ms commands in contact")
    parser.add_argument("-p", dest="overrides", action="append", default=[], metavar="NAME:=VALUE",
                        help="a liver_physics or haptic_bridge parameter, as for resimulate; repeatable")
    parser.add_argument("--out", type=Path, default=Path("out/fig8"), help="folder for the plots and fig8.json")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(handler=fig8)


def fig8(args) -> int:
    from liver_sim.analysis import fig8_line
    from liver_sim.sessions.fig8 import exploration_fig8

    figures = exploration_fig8(args.out, args.overrides, progress=(lambda line: None) if args.json else _progress)
    if args.json:
        print(json.dumps(figures))
        return 0
    steady = figures["smoothness_ratio_steady"]
    print(fig8_line(figures) + f"; in steady contact (touching and leaving left out) "
          f"{'n/a' if steady is None else f'{steady:.1f}x'}")
    return 0


def add_report_command(commands) -> None:
    """``liver-sim report BAG [--out DIR]``."""
    parser = commands.add_parser("report", help="plots and summary of a recorded or re-simulated session")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: BAG_report)")
    parser.set_defaults(handler=report)


def report(args) -> int:
    from liver_sim.sessions.report import write_report

    write_report(args.bag, _output(args, "_report"), _progress)
    return 0


def add_bag_command(commands) -> None:
    """``liver-sim bag repair BAG [--out DIR]``."""
    parser = commands.add_parser("bag", help="bag tools: repair a bag whose recorder was killed")
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    repair = actions.add_parser("repair", help="write a complete bag from what a damaged bag's storage file holds "
                                               "(the damaged bag is left as it is)")
    repair.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder (metadata.yaml may be missing)")
    repair.add_argument("--out", type=Path, default=None, help="new bag folder (default: BAG_repaired)")
    repair.set_defaults(handler=bag_repair)


def bag_repair(args) -> int:
    from liver_sim.sessions.bag import repair_bag

    repair_bag(args.bag, _output(args, "_repaired"), _progress)
    return 0


def add_bench_record_parser(kinds) -> None:
    """``liver-sim bench record [--json] [--duration S] [--storage …] [--out DIR] [--no-compare]``."""
    parser = kinds.add_parser("record", help="the closed loop while `liver-sim record` records it: recorder CPU "
                                             "share, haptic loop figures with and without it")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--duration", type=float, default=30.0, help="seconds of closed loop per run (default: 30)")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("out/bench_record"), help="folder for the bag and the logs")
    parser.add_argument("--no-compare", action="store_true", help="skip the first run without the recorder")
    parser.set_defaults(handler=bench_record)


def bench_record(args) -> int:
    from liver_sim.sessions.bench import run_record_bench

    report = run_record_bench(args.duration, args.out, args.storage, None if args.json else _progress,
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
        print(f"target {target} = {report['targets'][target]}: {'met' if met else 'NOT met'} while recording"
              + ("" if before is None else f" ({'met' if before else 'NOT met'} without)"))
    return 0
