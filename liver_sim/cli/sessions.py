"""The session subcommands of ``liver-sim``: record, replay, resimulate, report, fig8, bag repair (listed in
liver_sim.cli.main.COMMANDS). Like the other commands, each handler imports its modules when it runs
(liver_sim.cli.main says why)."""
from __future__ import annotations

import json
import time
from pathlib import Path

from liver_sim.cli.arguments import add_tools_argument
from liver_sim.sessions.bag import STORAGES


def _progress(line: str) -> None:
    print(line, flush=True)


def _output(args, suffix: str) -> Path:
    """--out, or a folder beside BAG named BAG<suffix>."""
    return args.out or args.bag.with_name(args.bag.name + suffix)


def add_record_command(commands) -> None:
    """``liver-sim record [--topics …] [--tools NAME …] [--storage mcap|sqlite3] [--out DIR] [--duration S]
    [--marker] [--realtime-priority N]``."""
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.sessions.record import REALTIME_PRIORITY

    parser = commands.add_parser("record", help="record the product's topics into a rosbag2 bag until Ctrl-C")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC",
                        help="topics to record (default: every topic of docs/contract.md but /liver/marker, and the "
                             "Fig. 8 baseline force)")
    parser.add_argument("--marker", action="store_true", help="also record /liver/marker (30 Hz skin triangles)")
    add_tools_argument(parser, "record")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None,
                        help="bag folder to create (default: out/sessions/session_<date>_<time>)")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds (default: on Ctrl-C)")
    parser.add_argument("--realtime-priority", type=int, default=REALTIME_PRIORITY, metavar="N",
                        help="SCHED_FIFO priority 1-99 of the recorder, below the nodes' so it never delays them and "
                             "above normal processes so they cannot starve it (default: %(default)s; 0: normal "
                             "scheduling; refused without CAP_SYS_NICE or an rtprio limit: a warning)")
    parser.set_defaults(handler=record)


def record(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.sessions.record import EXIT_LOST, default_topics, run_record

    out = args.out or Path("out/sessions") / time.strftime("session_%Y%m%d_%H%M%S")
    topics = args.topics or default_topics(args.marker, args.tools)
    if args.marker and args.topics and "/liver/marker" not in topics:
        topics.append("/liver/marker")
    _, failed = run_record(out, topics, args.storage, args.duration, _progress, args.realtime_priority)
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
    # this command's own modules, loaded when it runs (module docstring)
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
    # this command's own modules, loaded when it runs (module docstring)
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
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.sessions.analysis import fig8_line
    from liver_sim.studies.fig8 import exploration_fig8

    figures = exploration_fig8(args.out, args.overrides, progress=(lambda line: None) if args.json else _progress)
    if args.json:
        print(json.dumps(figures))
        return 0
    steady = figures["smoothness_ratio_steady"]
    print(fig8_line(figures) + f"; in steady contact (touching and leaving left out) "
          f"{'n/a' if steady is None else f'{steady:.1f}x'}")
    return 0


def add_report_command(commands) -> None:
    """``liver-sim report BAG [--out DIR] [--tool NAME]``."""
    parser = commands.add_parser("report", help="plots and summary of a recorded or re-simulated session")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: BAG_report)")
    parser.add_argument("--tool", default="", metavar="NAME",
                        help="the tool of a session with several (its topics under /NAME); default: the root "
                             "namespace's")
    parser.set_defaults(handler=report)


def report(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.sessions.report import write_report

    write_report(args.bag, _output(args, "_report"), _progress, args.tool)
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
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.sessions.bag import repair_bag

    repair_bag(args.bag, _output(args, "_repaired"), _progress)
    return 0
