"""Starting the product's nodes as separate processes, with the command lines a person would type.

No launch files: each node is `<executable> --ros-args --params-file config/<node>.yaml -p name:=value`.
"""
from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
from pathlib import Path

#: Discovery ranges of ROS 2 (ROS_AUTOMATIC_DISCOVERY_RANGE).
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT")
#: The range of every `liver-sim` command that starts ROS unless told otherwise: a demo or a replay next
#: to a rig must not reach its device.
DEFAULT_DISCOVERY_RANGE = "LOCALHOST"

NODE_MODULES = {"liver_physics": "liver_sim.nodes.physics_node", "haptic_bridge": "liver_sim.nodes.bridge_node",
                "liver_tool": "liver_sim.nodes.tool_node", "phantom_sim": "liver_sim.nodes.phantom_node"}


def keep_dds_local(discovery_range: str | None = None, environ=os.environ) -> str:
    """Set ROS_AUTOMATIC_DISCOVERY_RANGE for this process and every node it starts: `discovery_range` when
    given (the user's opt-out), else the environment's when set explicitly, else DEFAULT_DISCOVERY_RANGE.
    Returns the line to log: the domain and the range, and who chose it."""
    if discovery_range is not None:
        if discovery_range not in DISCOVERY_RANGES:
            raise ValueError(f"discovery range {discovery_range!r} must be one of {', '.join(DISCOVERY_RANGES)}")
        environ["ROS_AUTOMATIC_DISCOVERY_RANGE"], origin = discovery_range, "--discovery-range"
    elif environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE"):
        origin = "environment"
    else:
        environ["ROS_AUTOMATIC_DISCOVERY_RANGE"], origin = DEFAULT_DISCOVERY_RANGE, "liver-sim default"
    domain = environ.get("ROS_DOMAIN_ID") or "0 (unset)"
    return (f"ROS_DOMAIN_ID={domain}, ROS_AUTOMATIC_DISCOVERY_RANGE={environ['ROS_AUTOMATIC_DISCOVERY_RANGE']} "
            f"({origin})")


def config_dir() -> Path:
    """The folder of the parameter files: the source tree's config/, else the installed share/liver_sim/config."""
    source = Path(__file__).resolve().parent.parent / "config"
    if source.is_dir():
        return source
    return Path(sys.prefix) / "share" / "liver_sim" / "config"


def parameter_value(value) -> str:
    """A parameter value as `-p name:=value` takes it (YAML: lists in brackets, booleans in lower case)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(parameter_value(v) for v in value) + "]"
    if isinstance(value, float):
        return repr(float(value))
    return str(value)


def command_line(executable: str, overrides: dict | None = None, node_name: str | None = None) -> list[str]:
    """The node's command line: its console script (or `python -m` when not installed) and its ROS args."""
    script = Path(sys.executable).parent / executable
    program = [str(script)] if script.exists() else [sys.executable, "-m", NODE_MODULES[executable]]
    args = program + ["--ros-args", "--params-file", str(config_dir() / f"{executable}.yaml")]
    if node_name:
        args += ["-r", f"__node:={node_name}"]
    for name, value in (overrides or {}).items():
        args += ["-p", f"{name}:={parameter_value(value)}"]
    return args


def cli_command_line(*args: str) -> list[str]:
    """`liver-sim ARGS…` (its console script, or `python -m liver_sim.cli` when not installed)."""
    script = Path(sys.executable).parent / "liver-sim"
    program = [str(script)] if script.exists() else [sys.executable, "-m", "liver_sim.cli"]
    return program + list(args)


def printable(args: list[str]) -> str:
    """A command line as a shell would take it."""
    return " ".join(shlex.quote(a) for a in args)


class NodeProcesses:
    """Started node processes, stopped with SIGINT (then SIGTERM, then SIGKILL) on exit or stop()."""

    def __init__(self, log_dir: Path):
        self.log_dir = log_dir
        self.processes: dict[str, subprocess.Popen] = {}

    def start(self, label: str, args: list[str]) -> subprocess.Popen:
        """Start one node; its output goes to <log_dir>/<label>.log."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log = open(self.log_dir / f"{label}.log", "w")
        process = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ),
                                   start_new_session=True)
        log.close()
        self.processes[label] = process
        return process

    def stop(self, label: str | list[str] | None = None, timeout_s: float = 5.0) -> None:
        """Stop one node, a list of them, or all, politely first."""
        labels = [label] if isinstance(label, str) else list(self.processes if label is None else label)
        for name in labels:
            process = self.processes[name]
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for name in labels:
            process = self.processes[name]
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    process.wait(timeout=timeout_s)
                    break
                except subprocess.TimeoutExpired:
                    process.send_signal(sig)
            else:
                process.wait()

    def failed(self) -> dict[str, int]:
        """Nodes that have exited, with their exit status."""
        return {name: p.returncode for name, p in self.processes.items() if p.poll() is not None}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
