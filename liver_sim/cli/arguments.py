"""argparse types shared by the ``liver-sim`` subcommands."""
from __future__ import annotations

import argparse
import math

from liver_sim.base.topic_names import TOOL_NAME


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not positive")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"{value} is not a finite number > 0")
    return value


def tool_name(text: str) -> str:
    """argparse type: a tool's name, its namespace under the root (letters, digits and _, starting with a letter)."""
    if not TOOL_NAME.fullmatch(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not a tool name (letters, digits and _, starting with a "
                                         "letter)")
    return text


def add_tools_argument(parser, what: str) -> None:
    """--tools NAME …: the tools whose topics a command takes, each under /NAME (default: one in the root
    namespace, `[""]`)."""
    parser.add_argument("--tools", nargs="+", type=tool_name, default=[""], metavar="NAME",
                        help=f"the tools whose topics to {what}, each under /NAME (default: one tool in the root "
                             "namespace; `--tools left right` for two hands)")
