"""The live view's node (`liver_view`), at normal priority: it joins the user's domain as any viewer would, takes
the newest of each product topic (best effort, keep last one: it never holds a publisher back), each tool's in its
namespace (`tools`: one in the root namespace by default, or names, each under /NAME), and a RateLoop at
`rate_hz` (normal scheduling) builds the Scene (liver_sim.view.scene) and logs, on the Foxglove server's channels:

- `/liver/scene` (foxglove.SceneUpdate, frame `liver`; liver_sim.view.foxglove_scene): the skin coloured by
  displacement (`skin`), per tool its sphere (`tool`), its local model as a plane patch or a sphere
  (`local_model`), its contact force as an arrow (`force`) (`left/tool`, … for a named tool), the lips of cuts and
  tears (`lips`);
- `/liver/forces` (JSON): per tool the newest device force command (`phantom/servo_cf`) and physics contact force
  (`liver/tool_wrench`), their norms, for a Plot panel: the root tool's at the top level, a named tool's under its
  name (`left.device_command_norm_n`);
- `/liver/diagnostics` (JSON): each node's newest status, its level, message and key-values.

Each message is logged at the ROS time of the state it shows (the nodes' stamp). A malformed message is refused
and counted (`refused`), an exception in a tick counted (`tick_errors`); both are logged, throttled, and the view
goes on with the last good state. The server binds to a loopback address unless `allow_remote` (the view carries
no authentication).
"""
from __future__ import annotations

import ipaddress
import json
import threading
from contextlib import contextmanager

import foxglove
import numpy as np
from foxglove.channels import SceneUpdateChannel
from rclpy.node import Node

from liver_sim.base.topic_names import in_namespace, tool_namespace, tool_topic
from liver_sim.nodes.inputs import LoopInputs
from liver_sim.realtime.rate_loop import RateLoop
from liver_sim.view.defaults import DEFAULT_HOST, DEFAULT_PORT, VIEW_RATE_HZ
from liver_sim.view.foxglove_scene import scene_update
from liver_sim.view.scene import build_scene, lip_edges, scene_tool
from msg_defs.forces import force_from_bytes, force_message_type
from msg_defs.local_model import local_model_from_bytes
from msg_defs.point_cloud import pointcloud2_to_nodes
from msg_defs.poses import pose_from_bytes
from msg_defs.skin import mesh_msg_to_arrays
from msg_defs.stamps import seconds_from_stamp
from msg_defs.topics import TOPICS, loop_input_qos

#: The server's channels.
SCENE_TOPIC, FORCES_TOPIC, DIAGNOSTICS_TOPIC = "/liver/scene", "/liver/forces", "/liver/diagnostics"
LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
#: Seconds between two log lines of refused messages, and of failed ticks.
LOG_THROTTLE_S = 5.0


def check_host(host: str, allow_remote: bool) -> str:
    """`host` if it is a loopback address (or `localhost`), or any address with `allow_remote`; else ValueError."""
    if host == "localhost" or allow_remote:
        return host
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        raise ValueError(f"--host {host!r} is not an IP address; give a loopback address (127.0.0.1) or "
                         "--allow-remote to serve another interface") from None
    if not loopback:
        raise ValueError(f"--host {host} is not a loopback address: the view has no authentication, so anyone who "
                         "can reach it sees the session; pass --allow-remote to serve it there anyway")
    return host


class ToolInputs:
    """The newest state of one tool the view takes (in its namespace): tip, local model, physics force, device
    command."""

    def __init__(self, name: str):
        self.name = name
        self.tip = self.model = None
        self.physics_force = np.zeros(3)
        self.command = np.zeros(3)


class LiveView(Node):
    """Takes the product's topics and serves them as a Scene at `rate_hz` (module docstring). `on_scene(scene,
    stamp_ns)` is called with each scene built (the command's picture keeps the one with the largest force)."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, rate_hz: float = VIEW_RATE_HZ,
                 allow_remote: bool = False, on_scene=None, name: str = "liver_view", context=None, tools=("",)):
        super().__init__(name, context=context)
        self._lock = threading.Lock()
        self._skin = self._rest = self._lips = None
        self._nodes = None
        self._stamp_ns = 0
        self._tools = [ToolInputs(tool) for tool in tools]
        self._statuses: dict[str, dict] = {}
        #: scenes served, malformed messages refused, ticks that raised
        self.scenes = self.refused = 0
        self._on_scene = on_scene
        self._inputs = LoopInputs(self)
        self._inputs.subscribe(TOPICS["nodes"].type, TOPICS["nodes"].name, loop_input_qos(TOPICS["nodes"]),
                               self._on_nodes)
        for tool in self._tools:
            namespace = tool_namespace(tool.name)
            for key, on_message in (("tool_pose", self._on_pose), ("contact_plane", self._on_model),
                                    ("tool_wrench", self._on_wrench), ("servo_cf", self._on_command)):
                msg_type = TOPICS[key].type or force_message_type("wrench_stamped")
                self._inputs.subscribe(msg_type, in_namespace(tool_topic(key), namespace), loop_input_qos(TOPICS[key]),
                                       lambda data, tool=tool, on_message=on_message: on_message(tool, data), raw=True)
        self.create_subscription(TOPICS["surface"].type, TOPICS["surface"].name, self._on_surface,
                                 TOPICS["surface"].qos)
        self.create_subscription(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name, self._on_diagnostics,
                                 TOPICS["diagnostics"].qos)
        try:
            self.server = foxglove.start_server(name="liver_sim", host=check_host(host, allow_remote), port=port)
        except RuntimeError as exc:  # the address is taken or cannot be bound
            self._inputs.destroy()
            raise ValueError(f"--host {host} --port {port}: cannot serve there ({exc})") from None
        self._scene_channel = SceneUpdateChannel(SCENE_TOPIC)
        self._forces_channel = foxglove.Channel(FORCES_TOPIC, message_encoding="json")
        self._diagnostics_channel = foxglove.Channel(DIAGNOSTICS_TOPIC, message_encoding="json")
        self._loop = RateLoop(rate_hz, self._step, name, freeze=False, on_error=self._tick_failed,
                              context=self.context)
        self._loop.start()

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def tick_errors(self) -> int:
        """Ticks that raised (each logged, throttled); the loop went on."""
        return self._loop.errors

    def close(self) -> None:
        self._loop.stop()
        self._inputs.destroy()
        self.server.stop()

    # -- inputs (the loop's poll, or the executor for the surface and diagnostics)
    def _on_surface(self, message) -> None:
        with self._refused():
            skin, rest = mesh_msg_to_arrays(message)
            lips = lip_edges(rest, skin)
            with self._lock:
                self._skin, self._rest, self._lips = skin, rest, lips

    def _on_nodes(self, message) -> None:
        with self._refused():
            self._nodes = pointcloud2_to_nodes(message)
            self._stamp_ns = int(seconds_from_stamp(message.header.stamp) * 1e9)

    @contextmanager
    def _refused(self):
        """A malformed message is counted and logged (throttled): the view keeps showing the last good state."""
        try:
            yield
        except ValueError as exc:
            self.refused += 1
            self.get_logger().warning(f"view: ignored a message ({self.refused} so far): {exc}",
                                      throttle_duration_sec=LOG_THROTTLE_S)

    def _tick_failed(self, now: float, exc: Exception) -> None:
        """A tick that raised: counted by the loop, logged (throttled); the next tick runs as usual."""
        self.get_logger().error(f"view: a tick failed ({self.tick_errors} so far): {type(exc).__name__}: {exc}",
                                throttle_duration_sec=LOG_THROTTLE_S)

    def _on_pose(self, tool: ToolInputs, data: bytes) -> None:
        with self._refused():
            tool.tip = pose_from_bytes(data)[0]

    def _on_model(self, tool: ToolInputs, data: bytes) -> None:
        with self._refused():
            tool.model = local_model_from_bytes(data)[0]

    def _on_wrench(self, tool: ToolInputs, data: bytes) -> None:
        with self._refused():
            tool.physics_force = force_from_bytes("wrench_stamped", data)

    def _on_command(self, tool: ToolInputs, data: bytes) -> None:
        with self._refused():
            tool.command = force_from_bytes("wrench_stamped", data)

    def _on_diagnostics(self, message) -> None:
        for status in message.status:
            level = status.level[0] if isinstance(status.level, bytes) else int(status.level)
            self._statuses[status.name] = {"level": LEVELS.get(level, str(level)), "message": status.message,
                                           "values": {kv.key: kv.value for kv in status.values}}
        self._diagnostics_channel.log(json.dumps(self._statuses))

    # -- the loop
    def _step(self, now: float) -> None:
        self._inputs.poll()
        with self._lock:
            skin, rest, lips = self._skin, self._rest, self._lips
        nodes, stamp_ns = self._nodes, self._stamp_ns
        if skin is None or nodes is None or (len(skin) and skin.max() >= len(nodes)):
            return  # no surface yet, or nodes from before a topology change
        tools = tuple(scene_tool(tool.tip, local_model=tool.model, force_n=tool.physics_force, name=tool.name)
                      for tool in self._tools)
        scene = build_scene(nodes, rest, skin, lips, tools=tools)
        self._scene_channel.log(scene_update(scene, stamp_ns), log_time=stamp_ns)
        forces = {}
        for tool in self._tools:
            command, physics = tool.command, tool.physics_force
            values = {"device_command_n": command.tolist(), "device_command_norm_n": float(np.linalg.norm(command)),
                      "physics_force_n": physics.tolist(), "physics_force_norm_n": float(np.linalg.norm(physics))}
            forces.update({tool.name: values} if tool.name else values)
        self._forces_channel.log(json.dumps(forces), log_time=stamp_ns)
        self.scenes += 1
        if self._on_scene is not None:
            self._on_scene(scene, stamp_ns)


