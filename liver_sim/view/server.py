"""`liver-sim view`: the running network served to the Foxglove app over the Foxglove SDK's WebSocket server.

A node (`liver_view`) at normal priority joins the user's domain as any viewer would: it takes the newest of each
product topic (best effort, keep last one: it never holds a publisher back), and a RateLoop at `rate_hz` (normal
scheduling) builds the Scene (liver_sim.view.scene) and logs, on the server's channels:

- `/liver/scene` (foxglove.SceneUpdate, frame `liver`): the skin coloured by displacement (`skin`), the tool
  sphere (`tool`), the local model as a plane patch or a sphere (`local_model`), the contact force as an arrow
  (`force`), the lips of cuts and tears (`lips`);
- `/liver/forces` (JSON): the newest device force command (`/phantom/servo_cf`) and physics contact force
  (`/liver/tool_wrench`), their norms, for a Plot panel;
- `/liver/diagnostics` (JSON): each node's newest status, its level, message and key-values.

Each message is logged at the ROS time of the state it shows (the nodes' stamp). A malformed message is refused
and counted (`refused`), an exception in a tick counted (`tick_errors`); both are logged, throttled, and the view
goes on with the last good state. The server binds to a loopback address unless `allow_remote` (the view carries
no authentication).
"""
from __future__ import annotations

import ipaddress
import json
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import foxglove
import numpy as np
import rclpy
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.local_model import LocalModel
from liver_sim.base.stop_request import stop_on_signals
from liver_sim.nodes.inputs import LoopInputs
from liver_sim.nodes.rate_loop import RateLoop
from liver_sim.nodes.run import spin
from liver_sim.view.defaults import DEFAULT_HOST, DEFAULT_PORT, VIEW_RATE_HZ, VIEW_SERVED
from liver_sim.view.picture import draw_scene
from liver_sim.view.scene import (
    FORCE_COLOUR,
    LIPS_COLOUR,
    MODEL_COLOUR,
    TOOL_COLOUR,
    Scene,
    build_scene,
    force_arrow,
    plane_patch,
)
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


def _colour(rgba):
    r, g, b, a = (float(c) for c in rgba)
    return Color(r=r, g=g, b=b, a=a)


def _point(xyz):
    x, y, z = (float(c) for c in xyz)
    return Point3(x=x, y=y, z=z)


def _pose(position=(0.0, 0.0, 0.0), orientation_xyzw=(0.0, 0.0, 0.0, 1.0)):
    x, y, z, w = (float(c) for c in orientation_xyzw)
    px, py, pz = (float(c) for c in position)
    return Pose(position=Vector3(x=px, y=py, z=pz), orientation=Quaternion(x=x, y=y, z=z, w=w))


def arrow_orientation(direction: np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) turning +x (a Foxglove arrow's axis) onto `direction`."""
    d = direction / np.linalg.norm(direction)
    x_axis = np.array([1.0, 0.0, 0.0])
    cross, dot = np.cross(x_axis, d), float(x_axis @ d)
    if dot < -1.0 + 1e-9:
        return (0.0, 0.0, 1.0, 0.0)
    q = np.array([*cross, 1.0 + dot])
    q /= np.linalg.norm(q)
    return tuple(float(c) for c in q)


def scene_update(scene: Scene, stamp_ns: int, frame_id: str = "liver", points=None, indices=None):
    """The foxglove.SceneUpdate of `scene`: entities `skin`, `tool`, `local_model`, `force`, `lips` (an absent
    one is sent empty, so that the app removes what it showed). `points` and `indices`: the skin as node positions
    and triangle indices, when the caller has them (fewer points than three corners per triangle)."""
    stamp = Timestamp(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)

    def entity(name, **primitives):
        return SceneEntity(timestamp=stamp, frame_id=frame_id, id=name, **primitives)

    if points is None:
        corners, colours = scene.triangles.reshape(-1, 3), scene.colours.reshape(-1, 4)
        skin = TriangleListPrimitive(pose=_pose(), points=[_point(p) for p in corners],
                                     colors=[_colour(c) for c in colours])
    else:
        node_points, node_colours = points
        skin = TriangleListPrimitive(pose=_pose(), points=[_point(p) for p in node_points],
                                     colors=[_colour(c) for c in node_colours], indices=indices.ravel().tolist())
    entities = [entity("skin", triangles=[skin])]
    tool = []
    if scene.tool_tip_m is not None:
        d = 2.0 * scene.tool_radius_m
        tool = [SpherePrimitive(pose=_pose(scene.tool_tip_m), size=Vector3(x=d, y=d, z=d), color=_colour(TOOL_COLOUR))]
    entities.append(entity("tool", spheres=tool))
    model = scene.local_model
    patch, ball = [], []
    if model is not None and model.kind == "plane":
        corners = plane_patch(model).reshape(-1, 3)
        patch = [TriangleListPrimitive(pose=_pose(), points=[_point(p) for p in corners], color=_colour(MODEL_COLOUR))]
    elif model is not None:
        d = 2.0 * model.radius_m
        ball = [SpherePrimitive(pose=_pose(model.centre), size=Vector3(x=d, y=d, z=d), color=_colour(MODEL_COLOUR))]
    entities.append(entity("local_model", triangles=patch, spheres=ball))
    arrow = force_arrow(scene)
    arrows = []
    if arrow is not None:
        start, end = arrow
        length = float(np.linalg.norm(end - start))
        arrows = [ArrowPrimitive(pose=_pose(start, arrow_orientation(end - start)), shaft_length=0.8 * length,
                                 shaft_diameter=0.002, head_length=0.2 * length, head_diameter=0.005,
                                 color=_colour(FORCE_COLOUR))]
    entities.append(entity("force", arrows=arrows))
    lines = []
    if len(scene.lips):
        lines = [LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose(), thickness=2.0, scale_invariant=True,
                               points=[_point(p) for p in scene.lips.reshape(-1, 3)], color=_colour(LIPS_COLOUR))]
    entities.append(entity("lips", lines=lines))
    return SceneUpdate(entities=entities)


class LiveView(Node):
    """Takes the product's topics and serves them as a Scene at `rate_hz` (module docstring). `on_scene(scene,
    stamp_ns)` is called with each scene built (the command's picture keeps the one with the largest force)."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, rate_hz: float = VIEW_RATE_HZ,
                 allow_remote: bool = False, on_scene=None, name: str = "liver_view", context=None):
        super().__init__(name, context=context)
        self._lock = threading.Lock()
        self._skin = self._rest = self._initial_skin = None
        self._nodes = self._tip = self._model = None
        self._stamp_ns = 0
        self._command = np.zeros(3)
        self._physics_force = np.zeros(3)
        self._statuses: dict[str, dict] = {}
        #: scenes served, malformed messages refused, ticks that raised
        self.scenes = self.refused = 0
        self._on_scene = on_scene
        self._inputs = LoopInputs(self)
        self._inputs.subscribe(TOPICS["nodes"].type, TOPICS["nodes"].name, loop_input_qos(TOPICS["nodes"]),
                               self._on_nodes)
        self._inputs.subscribe(TOPICS["tool_pose"].type, TOPICS["tool_pose"].name,
                               loop_input_qos(TOPICS["tool_pose"]), self._on_pose, raw=True)
        self._inputs.subscribe(TOPICS["contact_plane"].type, TOPICS["contact_plane"].name,
                               loop_input_qos(TOPICS["contact_plane"]), self._on_model, raw=True)
        self._inputs.subscribe(TOPICS["tool_wrench"].type, TOPICS["tool_wrench"].name,
                               loop_input_qos(TOPICS["tool_wrench"]), self._on_wrench, raw=True)
        self._inputs.subscribe(force_message_type("wrench_stamped"), TOPICS["servo_cf"].name,
                               loop_input_qos(TOPICS["servo_cf"]), self._on_command, raw=True)
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
            with self._lock:
                if self._initial_skin is None:
                    self._initial_skin = skin
                self._skin, self._rest = skin, rest

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

    def _on_pose(self, data: bytes) -> None:
        with self._refused():
            self._tip = pose_from_bytes(data)[0]

    def _on_model(self, data: bytes) -> None:
        with self._refused():
            self._model = local_model_from_bytes(data)[0]

    def _on_wrench(self, data: bytes) -> None:
        with self._refused():
            self._physics_force = force_from_bytes("wrench_stamped", data)

    def _on_command(self, data: bytes) -> None:
        with self._refused():
            self._command = force_from_bytes("wrench_stamped", data)

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
            skin, rest, initial = self._skin, self._rest, self._initial_skin
        nodes, stamp_ns = self._nodes, self._stamp_ns
        if skin is None or nodes is None or (len(skin) and skin.max() >= len(nodes)):
            return  # no surface yet, or nodes from before a topology change
        model: LocalModel | None = self._model
        scene = build_scene(nodes, rest, skin, initial, self._tip, local_model=model, force_n=self._physics_force)
        colours = scene.colours.reshape(-1, 4)
        node_colours = np.zeros((len(nodes), 4))
        node_colours[skin.ravel()] = colours
        self._scene_channel.log(scene_update(scene, stamp_ns, points=(nodes, node_colours), indices=skin),
                                log_time=stamp_ns)
        command, physics = self._command, self._physics_force
        self._forces_channel.log(json.dumps({
            "device_command_n": command.tolist(), "device_command_norm_n": float(np.linalg.norm(command)),
            "physics_force_n": physics.tolist(), "physics_force_norm_n": float(np.linalg.norm(physics))}),
            log_time=stamp_ns)
        self.scenes += 1
        if self._on_scene is not None:
            self._on_scene(scene, stamp_ns)


def serve(host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, rate_hz: float = VIEW_RATE_HZ,
          allow_remote: bool = False, picture: Path | None = None, duration_s: float | None = None,
          progress=print) -> int:
    """`liver-sim view`: a LiveView until an ending signal (or `duration_s`); with `picture`, the scene with the
    largest contact force (the last one if none) drawn into that PNG at exit. Returns the scenes served."""
    check_host(host, allow_remote)
    kept = {}

    def keep(scene: Scene, stamp_ns: int) -> None:
        if "scene" not in kept or np.linalg.norm(scene.force_n) >= np.linalg.norm(kept["scene"].force_n):
            kept["scene"] = scene

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    view = None
    started = time.monotonic()
    try:
        with stop_on_signals() as stop:
            view = LiveView(host, port, rate_hz, allow_remote, keep if picture else None, context=context)
            executor = EventsExecutor(context=context)
            executor.add_node(view)
            progress(f"serving the live view on ws://{host}:{view.port} (Foxglove: Open connection → Foxglove "
                     f"WebSocket); {rate_hz:g} scenes/s; Ctrl-C stops")
            spinner = threading.Thread(target=spin, args=(executor, context, stop), daemon=True)
            spinner.start()
            stop.wait(duration_s)
            stop.set()
            spinner.join(timeout=2.0)
    finally:
        if view is not None:
            view.close()
            view.destroy_node()
        context.try_shutdown()
    elapsed = time.monotonic() - started
    scenes = view.scenes if view is not None else 0
    progress(f"{VIEW_SERVED} {scenes} scenes in {elapsed:.1f} s ({scenes / max(elapsed, 1e-9):.1f} per second)")
    if picture is not None and "scene" in kept:
        force = float(np.linalg.norm(kept["scene"].force_n))
        draw_scene(kept["scene"], picture, f"liver-sim view: the scene at the largest contact force ({force:.2f} N)")
        progress(f"wrote {picture}")
    elif picture is not None:
        print("liver-sim view: no scene was received (is the network running on this ROS_DOMAIN_ID?)",
              file=sys.stderr)
    return scenes
