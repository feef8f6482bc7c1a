"""Node processes of the product started by tests, and a test-side rclpy node that talks to them over DDS: every
wait bounded, nothing asserted on timing; a process is stopped with SIGINT, then SIGKILL."""
import signal
import subprocess
import sys
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from waiting import wait_for

from liver_sim.base.process_settings import NODE_MODULES
from msg_defs.topics import TOPICS

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: The bound (s) of every wait of a Ros session.
WAIT_S = 30.0


def value(v) -> str:
    """A parameter value as `-p name:=value` takes it."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ",".join(value(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


def command(executable: str, params: dict) -> list[str]:
    args = [sys.executable, "-m", NODE_MODULES[executable], "--ros-args", "--params-file",
            str(CONFIG / f"{executable}.yaml")]
    for name, v in params.items():
        args += ["-p", f"{name}:={value(v)}"]
    return args


def start(executable: str, params: dict, env: dict) -> subprocess.Popen:
    return subprocess.Popen(command(executable, params), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def stop(process: subprocess.Popen) -> str:
    """Stop a node (SIGINT, then SIGKILL); its stderr."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        _, err = process.communicate(timeout=5.0)
    except subprocess.TimeoutExpired:
        process.kill()
        _, err = process.communicate()
    return err


class Ros:
    """A test-side node in its own context: subscriptions that collect, publishers, bounded waits."""

    def __init__(self, name: str = "test_node"):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def collect(self, key: str, topic: str | None = None, msg_type=None) -> list:
        """Every message of the topic (its contract QoS, but a history of 1000: a test side starved of CPU, as on
        a busy machine, reads each sample late instead of only the newest of those it missed)."""
        received = []
        spec = TOPICS[key]
        qos = spec.qos
        qos.depth = max(qos.depth, 1000)
        self.node.create_subscription(msg_type or spec.type, topic or spec.name, received.append, qos)
        return received

    def wait_until(self, condition, what: str, process: subprocess.Popen | None = None) -> None:
        wait_for(condition, WAIT_S, what, between=lambda: self.executor.spin_once(timeout_sec=0.02),
                 gone=lambda: None if process is None or process.poll() is None else
                 f"the node exited ({process.returncode}): {process.stderr.read()}")

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)




def statuses(diagnostics: list, name: str) -> list[dict]:
    """The key-value pairs of every status called `name` in the DiagnosticArray messages `diagnostics`."""
    return [{kv.key: kv.value for kv in status.values}
            for array in diagnostics for status in array.status if status.name == name]
