"""`liver-sim bench floor`: what the 1 kHz hops of the network cost here with no work in them — the floor under
the nodes' CPU shares (`bench loop`), set by rclpy, Fast DDS and the machine, not by the product's own code.

Three processes built like the nodes (liver_sim.nodes.run.run_node: the same GIL switch interval, DDS profile,
garbage-collector policy; the product's RateLoop and LoopInputs):

- `source`: a 1 kHz RateLoop publishing a PoseStamped (as phantom_sim does, without the stylus);
- `relay`: republishes each source message at once from the executor (as liver_tool does, without the map);
- `loop`: a 1 kHz RateLoop taking the newest source message and publishing a WrenchStamped (as haptic_bridge
  does, without rendering or safety).

The rate loops run SCHED_FIFO at REALTIME_PRIORITY, as the nodes' do by default. `python -m liver_sim.bench.floor
ROLE` runs one role.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from rclpy.node import Node

from liver_sim.bench.machine import machine
from liver_sim.nodes.inputs import LoopInputs
from liver_sim.nodes.run import run_node
from liver_sim.realtime.rate_loop import RateLoop
from liver_sim.running.launcher import NodeProcesses
from liver_sim.running.network import process_costs, process_counters
from msg_defs.forces import force_message_type, wrench_stamped_bytes
from msg_defs.poses import pose_stamped_bytes
from msg_defs.topics import TOPICS, loop_input_qos

RATE_HZ = 1000.0
REALTIME_PRIORITY = 80
SOURCE, RELAYED, COMMAND = "/floor/source", "/floor/relayed", "/floor/command"
#: Seconds the processes get to discover each other before the window opens.
SETTLE_S = 5.0
_POSE = TOPICS["tool_pose"]


class FloorSource(Node):
    def __init__(self):
        super().__init__("floor_source")
        self._publisher = self.create_publisher(_POSE.type, SOURCE, _POSE.qos)
        self._loop = RateLoop(RATE_HZ, self._step, "floor_source", realtime_priority=REALTIME_PRIORITY)
        self._loop.start()

    def _step(self, now: float) -> None:
        stamp = self.get_clock().now().seconds_nanoseconds()
        self._publisher.publish(pose_stamped_bytes((0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0), stamp, "phantom_base"))

    def close(self) -> None:
        self._loop.stop()


class FloorRelay(Node):
    def __init__(self):
        super().__init__("floor_relay")
        self._publisher = self.create_publisher(_POSE.type, RELAYED, _POSE.qos)
        self.create_subscription(_POSE.type, SOURCE, self._publisher.publish, loop_input_qos(_POSE), raw=True)

    def close(self) -> None:
        pass


class FloorLoop(Node):
    def __init__(self):
        super().__init__("floor_loop")
        self._newest = None
        self._publisher = self.create_publisher(force_message_type("wrench_stamped"), COMMAND,
                                                TOPICS["tool_wrench"].qos)
        self._inputs = LoopInputs(self)
        self._inputs.subscribe(_POSE.type, SOURCE, loop_input_qos(_POSE), self._take, raw=True)
        self._zero = np.zeros(3)
        self._loop = RateLoop(RATE_HZ, self._step, "floor_loop", realtime_priority=REALTIME_PRIORITY)
        self._loop.start()

    def _take(self, data: bytes) -> None:
        self._newest = data

    def _step(self, now: float) -> None:
        self._inputs.poll()
        stamp = self.get_clock().now().seconds_nanoseconds()
        self._publisher.publish(wrench_stamped_bytes(self._zero, stamp, "phantom_base"))

    def close(self) -> None:
        self._loop.stop()
        self._inputs.destroy()


ROLES = {"source": FloorSource, "relay": FloorRelay, "loop": FloorLoop}


def run_floor_bench(duration_s: float = 20.0, log_dir: Path = Path("out/bench_floor/logs"), progress=None) -> dict:
    """The benchmark's JSON object: each role's share of one core and context switches over `duration_s`."""
    say = progress or (lambda line: None)
    with NodeProcesses(Path(log_dir), say) as processes:
        for role in ROLES:
            processes.start(role, [sys.executable, "-m", "liver_sim.bench.floor", role])
        time.sleep(SETTLE_S)
        processes.check("during start-up")
        pids = {label: process.pid for label, process in processes.processes.items()}
        before = {label: process_counters(pid) for label, pid in pids.items()}
        start = time.monotonic()
        time.sleep(duration_s)
        costs = process_costs(before, {label: process_counters(pid) for label, pid in pids.items()},
                              time.monotonic() - start)
        processes.check("while running")
    return {"benchmark": "floor", "machine": machine(), "duration_s": duration_s, "rate_hz": RATE_HZ,
            "processes": costs,
            "reading": "relay: a 1 kHz hop taken and republished by the executor (liver_tool's part); loop: a 1 kHz "
                       "rate loop taking one input and publishing one command (haptic_bridge's and phantom_sim's "
                       "part); each with no work of its own, so a node doing that hop costs at least this much"}


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) != 1 or argv[0] not in ROLES:
        print(f"usage: python -m liver_sim.bench.floor {{{','.join(ROLES)}}}", file=sys.stderr)
        return 2
    return run_node(ROLES[argv[0]], [])


if __name__ == "__main__":
    raise SystemExit(main())
