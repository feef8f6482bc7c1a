"""Running the four-node network as separate processes, listening to it, and stopping it cleanly.

Used by `liver-sim demo` and `liver-sim bench loop`.  Processes run in the ROS_DOMAIN_ID of the
environment and on loopback unless the environment says otherwise.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path


from liver_sim.mesh.liver_shape import default_liver
from liver_sim.processes import NodeProcesses, command_line, printable
from liver_sim.scenarios import press_anchor
from msg_defs.topics import BASELINE_FORCE_TOPIC

#: The scripted hand waits this long (s) before moving: DDS discovery of a new process takes seconds,
#: and the press must not begin before the tool node relays the stylus.
DEVICE_START_DELAY_S = 3.0


def default_anchor() -> list[float]:
    """Top of the default liver (m, liver frame): where the scripted hand presses."""
    return [round(float(v), 6) for v in press_anchor(default_liver())]


@dataclass
class NetworkPlan:
    """The command lines of one run: label -> argv."""

    commands: dict[str, list[str]] = field(default_factory=dict)
    force_topics: dict[str, tuple[str, str]] = field(default_factory=dict)
    #: started once the physics publishes, so that a scripted device does not press an absent liver
    after_physics: tuple = ("phantom_sim",)
    #: processes that watch the network (e.g. `liver-sim record`): started before the nodes, stopped after them
    observers: dict[str, list[str]] = field(default_factory=dict)


def closed_loop_plan(compare_without_local_model: bool = False, extra: dict | None = None) -> NetworkPlan:
    """The four nodes in closed loop with the simulated PHANToM pressing the top of the liver.

    With `compare_without_local_model`, a second bridge renders the physics wrench held between
    updates (`local_model: none`) on BASELINE_FORCE_TOPIC, from the same inputs (Fig. 8).
    `extra` maps an executable to more `-p` overrides.
    """
    extra = extra or {}
    plan = NetworkPlan()
    plan.commands["liver_physics"] = command_line("liver_physics", extra.get("liver_physics"))
    plan.commands["haptic_bridge"] = command_line("haptic_bridge", extra.get("haptic_bridge"))
    plan.commands["liver_tool"] = command_line("liver_tool", {"source": "device", **extra.get("liver_tool", {})})
    plan.commands["phantom_sim"] = command_line("phantom_sim", {"anchor_m": default_anchor(),
                                                                "start_delay_s": DEVICE_START_DELAY_S,
                                                                **extra.get("phantom_sim", {})})
    plan.force_topics["local_model"] = ("/phantom/servo_cf", "wrench_stamped")
    if compare_without_local_model:
        plan.commands["haptic_bridge_none"] = command_line(
            "haptic_bridge", {"local_model": "none", "force_topic": BASELINE_FORCE_TOPIC, "drives_device": False},
            node_name="haptic_bridge_without_local_model")
        plan.force_topics["without_local_model"] = (BASELINE_FORCE_TOPIC, "wrench_stamped")
    return plan


def run_network(plan: NetworkPlan, duration_s: float, log_dir: Path, progress=print,
                settle_s: float = 1.0) -> dict:
    """Start the plan's processes, listen for `duration_s` after they are up, stop them; return the snapshot
    (NetworkListener.snapshot) with `window_s`, the (start, end) of those `duration_s` (monotonic s).

    Raises RuntimeError naming any node that exited early (its log is in log_dir).
    """
    import rclpy
    from rclpy.experimental import EventsExecutor

    from liver_sim.nodes.common import spin
    from liver_sim.nodes.listener import NetworkListener

    progress(f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')} "
             f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '(default)')}")
    for label, args in {**plan.observers, **plan.commands}.items():
        progress(f"  {label}: {printable(args)}")
    context = rclpy.Context()
    rclpy.init(context=context)
    listener = NetworkListener(plan.force_topics, context=context)
    executor = EventsExecutor(context=context)
    executor.add_node(listener)
    spinner = threading.Thread(target=spin, args=(executor, context), daemon=True)
    spinner.start()
    processes = NodeProcesses(log_dir)
    try:
        present = len(listener.get_node_names())  # the listener's own nodes, and any left over in the domain
        for label, args in plan.observers.items():
            processes.start(label, args)
        _wait_until(listener, processes, f"the observers {', '.join(plan.observers)}",
                    lambda heard: len(heard.get_node_names()) >= present + len(plan.observers))
        for label, args in plan.commands.items():
            if label not in plan.after_physics:
                processes.start(label, args)
        _wait_until(listener, processes, "the network (node positions and every force topic)",
                    lambda heard: all(len(t) for t, _ in heard.snapshot()["forces"].values())
                    and len(heard.snapshot()["nodes_arrival_s"]))
        late = [label for label in plan.after_physics if label in plan.commands]
        for label in late:
            processes.start(label, plan.commands[label])
        if late:
            _wait_until(listener, processes, f"the tool pose from {', '.join(late)}",
                        lambda heard: len(heard.snapshot()["tool_arrival_s"]) > 0)
        time.sleep(settle_s)
        start = time.monotonic()
        while time.monotonic() - start < duration_s:
            time.sleep(min(1.0, duration_s - (time.monotonic() - start)))
            failed = processes.failed()
            if failed:
                raise RuntimeError(f"node(s) exited early: {failed}; see logs in {log_dir}")
            progress(f"  {time.monotonic() - start:5.1f} / {duration_s:.1f} s")
        return {**listener.snapshot(), "window_s": (start, time.monotonic())}
    finally:
        processes.stop([label for label in plan.commands if label in processes.processes])
        processes.stop()
        context.try_shutdown()
        spinner.join(timeout=2.0)
        listener.destroy_node()


def _wait_until(listener, processes: NodeProcesses, what: str, ready, timeout_s: float = 60.0) -> None:
    """Until `ready(listener)`; RuntimeError naming `what` after `timeout_s`, or naming a node that exited."""
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if ready(listener):
            return
        failed = processes.failed()
        if failed:
            raise RuntimeError(f"node(s) exited during start-up: {failed}; see logs in {processes.log_dir}")
        time.sleep(0.1)
    raise RuntimeError(f"{what} did not come up within {timeout_s:.0f} s; see logs in {processes.log_dir}")
