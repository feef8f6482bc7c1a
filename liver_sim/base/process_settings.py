"""Per-process settings of the product's processes (standard library only): real-time priority, the DDS
discovery range and profile, the folder of the parameter files, and the command lines that start a node or
`liver-sim`. Nodes, sessions and the launcher (liver_sim.running.launcher) share them.

No launch files: each node is `<executable> --ros-args --params-file config/<node>.yaml -p name:=value`.
"""
from __future__ import annotations

import os
import shlex
import sys
from contextlib import contextmanager
from pathlib import Path

#: Discovery ranges of ROS 2 (ROS_AUTOMATIC_DISCOVERY_RANGE).
DISCOVERY_RANGES = ("LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT")
#: The range of every `liver-sim` command that starts ROS unless told otherwise: a demo or a replay next
#: to a rig must not reach its device.
DEFAULT_DISCOVERY_RANGE = "LOCALHOST"

NODE_MODULES = {"liver_physics": "liver_sim.nodes.physics_node", "haptic_bridge": "liver_sim.nodes.bridge_node",
                "liver_tool": "liver_sim.nodes.tool_node", "phantom_sim": "liver_sim.nodes.phantom_node"}


def set_realtime_priority(priority: int) -> str | None:
    """Schedule the calling thread SCHED_FIFO at `priority` (0: leave it as it is).

    Only a thread that keeps a rate calls it, first thing, in itself: a node's rate loop, the bridge's
    supervisor, a machine-stall sentinel (and `liver-sim record` before rclpy starts, so that its DDS threads
    inherit it: a recording keeps every message). Every other thread — DDS's, the executor's,
    diagnostics — stays at normal priority beside the rig's own processes (a viewer, a recorder, controllers),
    which real-time threads that never sleep long would starve. Threads the caller starts afterwards inherit
    the priority. Returns None when done (or not asked), else why the system refused.
    """
    if priority <= 0:
        return None
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # 0: this thread, on Linux
    except OSError as exc:
        return (f"realtime_priority {priority} refused ({exc.strerror}): normal scheduling; grant CAP_SYS_NICE "
                f"or an rtprio limit to keep the rate under load")
    return None


#: The nice value of every thread of a node process that does not keep a rate (DDS's threads, the executor's): a
#: rate loop waits on them (a Fast DDS lock, the GIL), so an ordinary process must not starve them, while they take
#: no more than the work they are given.
SERVICE_NICE = -15


def set_service_nice(nice: int = SERVICE_NICE) -> str | None:
    """Give every thread of this process the nice value `nice` (SCHED_OTHER); threads they start afterwards inherit
    it.

    A node process calls it first thing, before rclpy starts DDS's threads: those threads and the executor's hold
    what the rate loops wait for (a Fast DDS writer's or participant's lock, the GIL), and at nice 0 a core-bound
    neighbour would take half their CPU while they hold it. A real-time loop is unaffected (SCHED_FIFO ignores
    nice). Returns None when done, else why the system refused."""
    try:
        for thread_id in os.listdir("/proc/self/task"):  # the interpreter's and the libraries' threads so far
            os.setpriority(os.PRIO_PROCESS, int(thread_id), nice)  # a thread id: that thread only, on Linux
    except OSError as exc:
        return (f"nice {nice} refused ({exc.strerror}): DDS's and the executor's threads stay at nice 0; grant "
                f"CAP_SYS_NICE or a nice limit (RLIMIT_NICE) so that other processes cannot starve them")
    return None


@contextmanager
def service_nice(nice: int = SERVICE_NICE):
    """:func:`set_service_nice` while the block runs (it gets None or the refusal), the calling thread's nice value
    back for every thread of the process after it."""
    previous = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        yield set_service_nice(nice)
    finally:
        for thread_id in os.listdir("/proc/self/task"):
            try:
                os.setpriority(os.PRIO_PROCESS, int(thread_id), previous)
            except OSError:  # a thread that ended meanwhile
                pass


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


#: The environment variable naming the Fast DDS XML profile every participant of the process loads.
DDS_PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
#: The product's Fast DDS profiles (config/), by discovery range: shared-memory ports whose health check waits
#: at most 33 ms instead of 333 ms while holding the participant's send lock (the files say why), and UDP on
#: loopback only (LOCALHOST, OFF) or on every interface (SUBNET, ROS's default, and SYSTEM_DEFAULT), so that the
#: physics and the bridge can run on two hosts.
DDS_PROFILE_FILES = {"LOCALHOST": "fastdds.xml", "OFF": "fastdds.xml", "SUBNET": "fastdds_network.xml",
                     "SYSTEM_DEFAULT": "fastdds_network.xml"}


def dds_profile_file(environ=os.environ) -> str:
    """The name of the product's profile for the discovery range `environ` gives (unset: SUBNET, ROS's default)."""
    return DDS_PROFILE_FILES.get(environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "SUBNET", "fastdds_network.xml")


def use_dds_profile(environ=os.environ) -> str:
    """Point DDS_PROFILE_VARIABLE at the product's Fast DDS profile for the process's discovery range
    (config_dir() / dds_profile_file()) for this process and every process it starts, unless the environment
    already names a profile (the user's choice stands). Call it after the range is settled (keep_dds_local) and
    before rclpy creates a participant. Returns the line to log: the profile, and who chose it."""
    if environ.get(DDS_PROFILE_VARIABLE):
        return f"{DDS_PROFILE_VARIABLE}={environ[DDS_PROFILE_VARIABLE]} (environment)"
    environ[DDS_PROFILE_VARIABLE] = str(config_dir() / dds_profile_file(environ))
    return f"{DDS_PROFILE_VARIABLE}={environ[DDS_PROFILE_VARIABLE]} (liver-sim default)"


def config_dir() -> Path:
    """The folder of the parameter files: the source tree's config/, else the installed share/liver_sim/config."""
    source = Path(__file__).resolve().parents[2] / "config"
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


def command_line(executable: str, overrides: dict | None = None, node_name: str | None = None,
                 namespace: str = "/") -> list[str]:
    """The node's command line: its console script (or `python -m` when not installed) and its ROS args; in
    `namespace` (`-r __ns:=`) unless the root."""
    script = Path(sys.executable).parent / executable
    program = [str(script)] if script.exists() else [sys.executable, "-m", NODE_MODULES[executable]]
    args = program + ["--ros-args"] + (["-r", f"__ns:={namespace}"] if namespace != "/" else [])
    args += ["--params-file", str(config_dir() / f"{executable}.yaml")]
    if node_name:
        args += ["-r", f"__node:={node_name}"]
    for name, value in (overrides or {}).items():
        args += ["-p", f"{name}:={parameter_value(value)}"]
    return args


def cli_command_line(*args: str) -> list[str]:
    """`liver-sim ARGS…` (its console script, or `python -m liver_sim.cli.main` when not installed)."""
    script = Path(sys.executable).parent / "liver-sim"
    program = [str(script)] if script.exists() else [sys.executable, "-m", "liver_sim.cli.main"]
    return program + list(args)


def printable(args: list[str]) -> str:
    """A command line as a shell would take it."""
    return " ".join(shlex.quote(a) for a in args)
