"""Running the four-node network as separate processes, listening to it, and stopping it cleanly: one physics and,
per tool, a device side (bridge, tool node, simulated PHANToM; in the tool's namespace when it has a name).

Used by `liver-sim demo` and `liver-sim bench loop`.  Processes run in the ROS_DOMAIN_ID of the
environment and on loopback unless the environment says otherwise.
"""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import rclpy
from rclpy.experimental import EventsExecutor

from liver_sim.base.process_settings import command_line, printable, service_nice
from liver_sim.base.topic_names import in_namespace, tool_namespace, tool_topic
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.nodes.occupants import refuse_occupied
from liver_sim.nodes.run import spin
from liver_sim.running.launcher import NodeProcesses, die_with_parent, log_tail
from liver_sim.running.listener import NetworkListener, NetworkSnapshot
from liver_sim.running.machine_stalls import Sentinels, gaps_with_stalls
from liver_sim.sessions.analysis import rate_figures
from liver_sim.sessions.record import READY, RECORDER_NODE, default_topics

#: How often (s) the listener decodes what it received during a run (and lets the bytes go).
DECODE_EVERY_S = 10.0
#: The scripted hand waits this long (s) before moving: DDS discovery of a new process takes seconds,
#: and the press must not begin before the tool node relays the stylus.
DEVICE_START_DELAY_S = 3.0


def default_anchor() -> list[float]:
    """Top of the default liver (m, liver frame): where the scripted hand presses."""
    return [round(float(v), 6) for v in press_anchor(default_liver())]


@dataclass
class NetworkPlan:
    """The command lines of one run: label -> argv; the force topics listened to (label -> (topic, format)) and the
    namespace of each label's device side (NetworkListener)."""

    commands: dict[str, list[str]] = field(default_factory=dict)
    force_topics: dict[str, tuple[str, str]] = field(default_factory=dict)
    namespaces: dict[str, str] = field(default_factory=dict)
    #: started once the physics publishes, so that a scripted device does not press an absent liver
    after_physics: tuple = ("phantom_sim",)
    #: `liver-sim record` command lines: started before the nodes, which start once each has printed its
    #: READY line and its subscriptions show in the graph; stopped after the nodes, given the time they need
    observers: dict[str, list[str]] = field(default_factory=dict)


#: The label of the one device side in the root namespace (a named tool's label is its name).
ROOT_LABEL = "local_model"
#: The executables of a device side.
DEVICE_SIDE = ("haptic_bridge", "liver_tool", "phantom_sim")


def side_label(executable: str, tool: str) -> str:
    """The label of a device side's process: the executable, after an underscore its tool's name if it has one."""
    return f"{executable}_{tool}" if tool else executable


def closed_loop_plan(extra: dict | None = None, tools: dict[str, dict] | None = None) -> NetworkPlan:
    """The physics and, per tool, a bridge, a tool node and the simulated PHANToM pressing the top of the liver, in
    closed loop: one tool in the root namespace by default (the four nodes), or `tools`, {name: {executable: more
    `-p` overrides of that tool's side; for liver_physics its NAME.<name> parameters}}, each side in /NAME.

    `extra` maps an executable to more `-p` overrides (of every side).  (Fig. 8's baseline bridge without local
    model runs offline on what the network sent: analysis.held_wrench_baseline, `liver-sim resimulate --compare`.)
    """
    extra, tools = extra or {}, tools or {"": {}}
    plan = NetworkPlan()
    physics = dict(extra.get("liver_physics", {}))
    if list(tools) != [""]:
        physics["tools"] = list(tools)
        physics.update({f"{tool}.{name}": value for tool, own in tools.items()
                        for name, value in own.get("liver_physics", {}).items()})
    plan.commands["liver_physics"] = command_line("liver_physics", physics)
    base = {"haptic_bridge": {}, "liver_tool": {"source": "device"},
            "phantom_sim": {"anchor_m": default_anchor(), "start_delay_s": DEVICE_START_DELAY_S}}
    for tool, own in tools.items():
        namespace = tool_namespace(tool)
        for executable in DEVICE_SIDE:
            plan.commands[side_label(executable, tool)] = command_line(
                executable, {**base[executable], **extra.get(executable, {}), **own.get(executable, {})},
                namespace=namespace)
        label = tool or ROOT_LABEL
        plan.force_topics[label] = (in_namespace(tool_topic("servo_cf"), namespace), "wrench_stamped")
        plan.namespaces[label] = namespace
    plan.after_physics = tuple(side_label("phantom_sim", tool) for tool in tools)
    return plan


#: Several scripted devices (plan.after_physics) start their scripts together this long (s) after they are launched:
#: more than a node takes to load on a busy 2-core machine, so that none starts its script late.
SCRIPTS_START_AFTER_S = 4.0


#: A process that keeps one core busy at normal priority (`extra_load`): what a person runs beside the rig.
CORE_BOUND_PROCESS = [sys.executable, "-c", "while True: pass"]


def process_counters(pid: int) -> dict | None:
    """CPU time (s, user + system, all threads: /proc/<pid>/stat) and voluntary and involuntary context
    switches (summed over /proc/<pid>/task/*/status) of `pid`; None when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        switches = {"voluntary_ctxt_switches": 0, "nonvoluntary_ctxt_switches": 0}
        for task in Path(f"/proc/{pid}/task").iterdir():
            try:
                for line in (task / "status").read_text().splitlines():
                    key, _, value = line.partition(":")
                    if key in switches:
                        switches[key] += int(value)
            except OSError:  # a thread that ended meanwhile
                continue
    except OSError:
        return None
    return {"cpu_s": (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK"),
            "voluntary": switches["voluntary_ctxt_switches"], "involuntary": switches["nonvoluntary_ctxt_switches"]}


def process_costs(before: dict, after: dict, wall_s: float) -> dict:
    """{label: cpu_share_of_one_core, voluntary_switches_per_s, involuntary_switches_per_s} between two
    samples {label: process_counters(pid)} taken `wall_s` apart; labels missing from either are left out."""
    costs = {}
    for label, first in before.items():
        last = after.get(label)
        if first is None or last is None:
            continue
        costs[label] = {"cpu_share_of_one_core": (last["cpu_s"] - first["cpu_s"]) / wall_s,
                        "voluntary_switches_per_s": (last["voluntary"] - first["voluntary"]) / wall_s,
                        "involuntary_switches_per_s": (last["involuntary"] - first["involuntary"]) / wall_s}
    return costs


@dataclass(frozen=True)
class NetworkRun(NetworkSnapshot):
    """What `run_network` returns: everything the listener received (NetworkSnapshot, the nodes' last
    messages while they stopped included), and the window in which every node ran."""

    #: (start, end) monotonic s of the `duration_s` in which every node ran; figures on the wire use it
    window_s: tuple[float, float]
    #: label -> {cpu_share_of_one_core, voluntary_switches_per_s, involuntary_switches_per_s} over the window
    #: (:func:`process_costs`), for each node, observer, `listener` (the calling process) and extra load
    process_costs: dict
    #: (K, 2) start and end (monotonic s) of each stall of the machine itself within the window
    machine_stalls: np.ndarray
    #: when the nodes were asked to stop (ns since the epoch: the system clock of DDS source times); a stop keeps
    #: every message a node published before it (docs/contract.md, "Processes of a run")
    stop_requested_ns: int


def run_network(plan: NetworkPlan, duration_s: float, log_dir: Path, progress=print,
                settle_s: float = 1.0, extra_load: int = 0, check_domain: bool = True) -> NetworkRun:
    """Start the plan's processes, listen for `duration_s` after they are up, stop them; return a NetworkRun:
    what the listener received, the window of those `duration_s`, what each process cost over it (each node,
    observer, `listener` — this process — and each of the `extra_load` CORE_BOUND_PROCESSes started at normal
    priority once the network is up), and the stalls of the machine within it, measured by a sentinel per CPU
    (liver_sim.running.machine_stalls).

    With `check_domain` (the default), first refuses a domain where a product node or a device already runs
    (nodes.occupants.refuse_occupied: DomainOccupied, after up to DISCOVERY_WAIT_S); a series of runs checks before
    its first only (the domain then holds the series' own nodes, stopping).

    Raises NodeFailure naming any process that exited early or with a non-zero status at stop, with the tail
    of its log (in log_dir); RuntimeError if the network does not come up.

    The listener measures the run: while it runs, this process's threads (its DDS threads included) are at
    SERVICE_NICE, as a node's are, so that an ordinary process beside the run does not starve it.
    """
    with service_nice() as refused:
        if refused:
            progress(f"  {refused}")
        return _listen_to(plan, duration_s, log_dir, progress, settle_s, extra_load, check_domain)


def _listen_to(plan: NetworkPlan, duration_s: float, log_dir: Path, progress, settle_s: float, extra_load: int,
               check_domain: bool) -> NetworkRun:
    """run_network's run, at the nice value it chose."""
    progress(f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')} "
             f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '(default)')}")
    for label, args in {**plan.observers, **plan.commands}.items():
        progress(f"  {label}: {printable(args)}")
    context = rclpy.Context()
    rclpy.init(context=context)
    listener = NetworkListener(plan.force_topics, context=context, namespaces=plan.namespaces)
    executor = EventsExecutor(context=context)
    executor.add_node(listener)
    spinner = threading.Thread(target=spin, args=(executor, context), daemon=True)
    spinner.start()
    processes = None
    loads = []
    sentinels = Sentinels(log_dir)
    try:
        processes = NodeProcesses(log_dir, progress)  # first stops what a dead run of this user left
        if check_domain:
            refuse_occupied(listener, "this run")
        for label, args in plan.observers.items():
            processes.start(label, args, patient=True)
        recorded = default_topics(tools=[namespace.strip("/") for namespace in plan.namespaces.values()])
        _wait_until(listener, processes, f"the recorder(s) {', '.join(plan.observers)} (ready and subscribed)",
                    lambda heard: all(_recorder_ready(heard, log_dir / f"{label}.log", recorded)
                                      for label in plan.observers))
        for label, args in plan.commands.items():
            if label not in plan.after_physics:
                processes.start(label, args)
        _wait_until(listener, processes, "the network (node positions and every force topic)",
                    lambda heard: all(len(t) for t, _ in heard.snapshot().forces.values())
                    and len(heard.snapshot().nodes_arrival_s))
        late = [label for label in plan.after_physics if label in plan.commands]
        together = []
        if len(late) > 1:  # several scripted devices play their scripts from one start, however long each loads
            start_s = listener.get_clock().now().nanoseconds * 1e-9 + SCRIPTS_START_AFTER_S
            together = ["-p", f"script_start_time_s:={start_s:.6f}"]
        for label in late:
            processes.start(label, plan.commands[label] + together)
        if late:
            _wait_until(listener, processes, f"the device samples from {', '.join(late)}",
                        lambda heard: all(len(a) for a in heard.snapshot().device_arrival_s.values()))
        for k in range(extra_load):
            loads.append(subprocess.Popen(CORE_BOUND_PROCESS, preexec_fn=die_with_parent(os.getpid())))
            progress(f"  extra load {k + 1}: pid {loads[-1].pid}, one core busy at normal priority")
        sentinels.start()  # once the network is up: they watch the window
        time.sleep(settle_s)
        pids = {label: process.pid for label, process in processes.processes.items()}
        pids.update({"listener": os.getpid(), **{f"extra_load_{k + 1}": p.pid for k, p in enumerate(loads)}})
        before = {label: process_counters(pid) for label, pid in pids.items()}
        start = time.monotonic()
        decoded = start
        while time.monotonic() - start < duration_s:
            time.sleep(min(1.0, duration_s - (time.monotonic() - start)))
            if time.monotonic() - decoded >= DECODE_EVERY_S:
                listener.decode()  # its memory stays bounded however long the run
                decoded = time.monotonic()
            processes.check("while running")
            progress(f"  {time.monotonic() - start:5.1f} / {duration_s:.1f} s")
        window = (start, time.monotonic())
        costs = process_costs(before, {label: process_counters(pid) for label, pid in pids.items()},
                              window[1] - window[0])
    finally:
        sentinels.stop()
        for load in loads:
            load.kill()
            load.wait()
        stop_requested_ns = time.time_ns()
        if processes is not None:
            processes.stop([label for label in plan.commands if label in processes.processes])
            if plan.observers:
                progress("  nodes stopped; waiting for the recorder to close its bag")
            processes.stop()
        snapshot = listener.snapshot()  # with what the nodes sent while they stopped
        context.try_shutdown()
        spinner.join(timeout=2.0)
        listener.destroy_node()
    processes.check_exit_codes()
    return NetworkRun(**{f.name: getattr(snapshot, f.name) for f in fields(NetworkSnapshot)}, window_s=window,
                      process_costs=costs, machine_stalls=sentinels.stalls(window), stop_requested_ns=stop_requested_ns)


def wire_rates(run: NetworkRun, label: str = ROOT_LABEL) -> dict:
    """The network's rates as its messages went on the wire (DDS publication times) within the run's
    `window_s`, the `duration_s` in which every node ran: {'physics': rate_figures of /liver/nodes at 150 Hz,
    'haptic': of the `label` force commands at 1 kHz}. Start-up, shutdown and a listener's batched arrivals
    do not count."""

    start, end = run.window_s
    nodes, forces = run.nodes_published_s, run.force_published_s[label]
    return {"physics": rate_figures(nodes[(nodes >= start) & (nodes <= end)], 150.0),
            "haptic": rate_figures(forces[(forces >= start) & (forces <= end)], 1000.0)}


def wire_gaps(run: NetworkRun, bound_s: float, label: str = ROOT_LABEL) -> list[dict]:
    """The gaps longer than `bound_s` between the `label` force commands published within the run's
    `window_s`, each with the part of it the machine stalled (machine_stalls.gaps_with_stalls; `start_s` from
    the window's start)."""

    start, end = run.window_s
    sent = run.force_published_s[label]
    gaps = gaps_with_stalls(sent[(sent >= start) & (sent <= end)], bound_s, run.machine_stalls)
    return [{**gap, "start_s": gap["start_s"] - start} for gap in gaps]


def _recorder_ready(listener, log: Path, topics: list[str]) -> bool:
    """Whether the recorder logging to `log` said READY and the graph shows its subscriptions to `topics`."""

    if not any(line.startswith(READY) for line in log_tail(log, 1000)):
        return False
    return all(any(s.node_name == RECORDER_NODE for s in listener.get_subscriptions_info_by_topic(topic))
               for topic in topics)


def _wait_until(listener, processes: NodeProcesses, what: str, ready, timeout_s: float = 60.0) -> None:
    """Until `ready(listener)`; RuntimeError naming `what` after `timeout_s`, or naming a node that exited."""
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if ready(listener):
            return
        processes.check("during start-up")
        time.sleep(0.1)
    raise RuntimeError(f"{what} did not come up within {timeout_s:.0f} s; see logs in {processes.log_dir}")
