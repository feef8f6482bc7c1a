"""The session subcommands of ``liver-sim``: record, replay, resimulate, report (listed in cli.COMMANDS)."""
from __future__ import annotations

from pathlib import Path

from liver_sim.sessions.bag import STORAGES


def _progress(line: str) -> None:
    print(line, flush=True)


def add_record_command(commands) -> None:
    """``liver-sim record [--topics …] [--storage mcap|sqlite3] [--out DIR] [--duration S] [--marker]``."""
    parser = commands.add_parser("record", help="record the product's topics into a rosbag2 bag until Ctrl-C")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC",
                        help="topics to record (default: every topic of DESIGN.md but /liver/marker, and the "
                             "Fig. 8 baseline force)")
    parser.add_argument("--marker", action="store_true", help="also record /liver/marker (30 Hz skin triangles)")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None,
                        help="bag folder to create (default: out/sessions/session_<date>_<time>)")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds (default: on Ctrl-C)")
    parser.set_defaults(handler=record)


def record(args) -> int:
    import time

    from liver_sim.sessions.record import default_topics, run_record

    out = args.out or Path("out/sessions") / time.strftime("session_%Y%m%d_%H%M%S")
    topics = args.topics or default_topics(marker=args.marker)
    if args.marker and args.topics and "/liver/marker" not in topics:
        topics.append("/liver/marker")
    run_record(out, topics, args.storage, args.duration, _progress)
    return 0


def add_replay_command(commands) -> None:
    """``liver-sim replay BAG [--rate R] [--topics …] [--delay S]``."""
    parser = commands.add_parser("replay", help="republish a bag's topics with their original timing")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default: 1)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics (default: all in the bag); "
                        "e.g. /phantom/measured_cp to drive liver_tool with a past session's device")
    parser.add_argument("--delay", type=float, default=1.0,
                        help="seconds to wait for subscribers before the first message (default: 1)")
    parser.set_defaults(handler=replay)


def replay(args) -> int:
    from liver_sim.sessions.replay import run_replay

    run_replay(args.bag, args.rate, args.topics, args.delay, _progress)
    return 0


def add_resimulate_command(commands) -> None:
    """``liver-sim resimulate BAG [-p name:=value …] [--out BAG2] [--storage …]``."""
    parser = commands.add_parser("resimulate", help="re-run physics and haptic bridge offline on a bag's tool poses")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder holding /tool/pose")
    parser.add_argument("-p", dest="overrides", action="append", default=[], metavar="NAME:=VALUE",
                        help="a liver_physics or haptic_bridge parameter (prefix liver_physics. or haptic_bridge. "
                             "to set only one node's); repeatable")
    parser.add_argument("--out", type=Path, default=None, help="output bag folder (default: BAG_resimulated)")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="output storage (default: %(default)s)")
    parser.set_defaults(handler=resimulate)


def resimulate(args) -> int:
    from liver_sim.sessions.resimulate import resimulate as run

    out = args.out or args.bag.with_name(args.bag.name + "_resimulated")
    run(args.bag, out, args.overrides, args.storage, _progress)
    return 0


def add_report_command(commands) -> None:
    """``liver-sim report BAG [--out DIR]``."""
    parser = commands.add_parser("report", help="plots and summary of a recorded or re-simulated session")
    parser.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 bag folder")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: BAG_report)")
    parser.set_defaults(handler=report)


def report(args) -> int:
    from liver_sim.sessions.report import write_report

    write_report(args.bag, args.out or args.bag.with_name(args.bag.name + "_report"), _progress)
    return 0
