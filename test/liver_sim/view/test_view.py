"""The live view: its scene (no ROS), its Foxglove messages read back as the app reads them, its address check, the
view of a running network through a real Foxglove WebSocket client, and recorded sessions Foxglove can open."""
import json
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from foxglove_client import VIEW_TOPICS, field_numbers, fields, packed_count, schema_bytes
from waiting import POLL_S, wait_for

from liver_sim.base.local_model import LocalModel
from liver_sim.base.process_settings import config_dir
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.view import scene as scene_module
from liver_sim.view.scene import (
    DISPLACED_COLOUR,
    REST_COLOUR,
    build_scene,
    force_arrow,
    lip_edges,
    opened_triangles,
    plane_patch,
    scene_tool,
)

LIVER = default_liver()
PLANE = LocalModel("plane", True, np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.6, 0.8]), np.zeros(3), 0.0, 0.002,
                   True, None)


def test_the_scene_holds_every_skin_triangle_coloured_by_its_displacement():
    moved = LIVER.points.copy()
    moved[LIVER.skin[0]] += [0.0, 0.0, -0.02]  # beyond the colour's scale
    scene = build_scene(moved, LIVER.points, LIVER.skin, lip_edges(LIVER.points, LIVER.skin),
                        np.array([0.0, 0.0, 0.1]), 0.015, PLANE, np.array([0.0, 0.0, 0.5]))
    assert scene.triangle_count == len(LIVER.skin) and scene.triangles.shape == (len(LIVER.skin), 3, 3)
    assert scene.colours.shape == (len(LIVER.points), 4)          # one colour per node
    assert scene.colours[LIVER.skin[0]] == pytest.approx(np.tile(DISPLACED_COLOUR, (3, 1)))
    untouched = ~np.isin(LIVER.skin, LIVER.skin[0]).any(axis=1)
    assert np.allclose(scene.colours[LIVER.skin[untouched]], REST_COLOUR)
    assert len(scene.lips) == 0                                    # no topology change
    start, end = force_arrow(scene.tools[0])
    assert end - start == pytest.approx([0.0, 0.0, 0.5 * scene_module.ARROW_M_PER_N])


def test_a_plane_patch_lies_in_its_plane_around_its_point():
    corners = plane_patch(PLANE).reshape(-1, 3)
    assert (corners - PLANE.point) @ PLANE.normal == pytest.approx(np.zeros(6), abs=1e-12)
    half_diagonal = scene_module.PLANE_PATCH_M / np.sqrt(2.0)
    assert np.linalg.norm(corners - PLANE.point, axis=1) == pytest.approx(np.full(6, half_diagonal))


def test_lips_are_the_rim_of_the_triangles_a_cut_opened():
    """The lips: the edges between the triangles a cut opened (twins at rest: the opening duplicated their nodes in
    place) and the original skin; none before the cut."""
    from liver_sim.physics.model import LiverModel

    model = LiverModel(LIVER)
    assert len(lip_edges(LIVER.points, LIVER.skin)) == 0 and not opened_triangles(LIVER.points, LIVER.skin).any()
    top = LIVER.points[LIVER.skin_nodes][np.argmax(LIVER.points[LIVER.skin_nodes, 2])]
    assert model.cut(np.array([top - [0.03, 0.0, 0.0], top + [0.03, 0.0, 0.0]]), 0.01)
    rest, skin = model.structure.mesh.points, model.structure.mesh.skin
    opened = opened_triangles(rest, skin)
    assert 0 < opened.sum() < len(skin)

    def edges(triangles):
        return {tuple(sorted(e)) for t in triangles.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    rim = {tuple(e) for e in lip_edges(rest, skin).tolist()}
    assert rim and rim == edges(skin[opened]) & edges(skin[~opened])
    scene = build_scene(model.state.positions, rest, skin, lip_edges(rest, skin))
    assert scene.lips.shape == (len(rim), 2, 3)


@pytest.mark.parametrize("host, allowed", [("127.0.0.1", True), ("localhost", True), ("::1", True),
                                           ("0.0.0.0", False), ("192.168.1.20", False), ("liver.example", False)])
def test_a_non_loopback_address_is_refused_unless_asked_for(host, allowed):
    from liver_sim.view.live_view import check_host

    if allowed:
        assert check_host(host, False) == host
    else:
        with pytest.raises(ValueError, match="--allow-remote"):
            check_host(host, False)
        assert check_host(host, True) == host


def decode_scene(payload: bytes, schema: bytes) -> dict:
    """{entity id: {primitive field name: [primitive bytes]}} of a serialized foxglove.SceneUpdate."""
    numbers = field_numbers(schema)
    update, entity = numbers["SceneUpdate"], numbers["SceneEntity"]
    names = {number: name for name, number in entity.items()}
    entities = {}
    for number, _, value in fields(payload):
        if number != update["entities"]:
            continue
        parts = fields(value)
        name = next(v.decode() for n, _, v in parts if n == entity["id"])
        entities[name] = {}
        for n, _, v in parts:
            if names.get(n) in ("triangles", "spheres", "arrows", "lines"):
                entities[name].setdefault(names[n], []).append(v)
    return entities


def skin_triangles(entities: dict, schema: bytes) -> int:
    """Triangles of the scene's `skin` entity: its indices over three, or its points over three without indices."""
    numbers = field_numbers(schema)["TriangleListPrimitive"]
    (skin,) = entities["skin"]["triangles"]
    parts = fields(skin)
    indices = [v for n, _, v in parts if n == numbers["indices"]]
    if indices:
        return packed_count(b"".join(indices), field_numbers(schema, what=5)["TriangleListPrimitive"]["indices"]) // 3
    return sum(1 for n, _, _ in parts if n == numbers["points"]) // 3


def test_scene_updates_read_back_with_the_advertised_schema():
    """The message the view logs, read as the app reads it: by the field numbers of the schema it advertises."""
    from foxglove.messages import SceneUpdate

    from liver_sim.view.foxglove_scene import scene_update

    scene = build_scene(LIVER.points, LIVER.points, LIVER.skin, None, np.array([0.0, 0.0, 0.1]), 0.015, PLANE,
                        np.array([0.0, 0.0, 0.4]))
    schema = SceneUpdate.get_schema()
    assert schema.name == "foxglove.SceneUpdate" and schema.encoding == "protobuf"
    entities = decode_scene(scene_update(scene, 1_500_000_000).encode(), bytes(schema.data))
    assert set(entities) == {"skin", "tool", "local_model", "force", "lips"}
    assert skin_triangles(entities, bytes(schema.data)) == len(LIVER.skin)
    assert len(entities["tool"]["spheres"]) == 1 and len(entities["force"]["arrows"]) == 1
    assert len(entities["local_model"]["triangles"]) == 1 and "lines" not in entities["lips"]


def test_two_tools_show_each_with_its_local_model_and_force(tmp_path):
    """Two hands: each tool's sphere, local model and force arrow, under its name; the picture draws both."""
    from foxglove.messages import SceneUpdate

    from liver_sim.view.foxglove_scene import scene_update
    from liver_sim.view.picture import draw_scene

    tools = (scene_tool(np.array([-0.04, 0.0, 0.08]), local_model=PLANE, force_n=np.array([0.0, 0.0, -1.5]),
                        name="left"),
             scene_tool(np.array([0.03, 0.0, 0.06]), force_n=np.array([0.0, 0.0, 0.7]), name="right"))
    scene = build_scene(LIVER.points, LIVER.points, LIVER.skin, None, tools=tools)
    assert scene.largest_force_n == pytest.approx(1.5) and scene.tools[0].tool_tip_m[0] == pytest.approx(-0.04)
    schema = SceneUpdate.get_schema()
    entities = decode_scene(scene_update(scene, 1_500_000_000).encode(), bytes(schema.data))
    assert {"left/tool", "left/local_model", "left/force", "right/tool", "right/local_model", "right/force"} <= set(
        entities)
    assert len(entities["left/local_model"]["triangles"]) == 1 and "triangles" not in entities["right/local_model"]
    assert len(entities["right/force"]["arrows"]) == 1 and len(entities["left/tool"]["spheres"]) == 1
    assert draw_scene(scene, tmp_path / "two.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.no_rate_loops
def test_the_live_view_refuses_a_bad_mesh_and_goes_on_after_a_failing_tick(ros_domain_id):
    """A running view fed a shape_msgs/Mesh whose triangles index missing vertices refuses and counts it and keeps
    serving scenes of the last good surface; a tick that raises is counted and the next ticks serve as before."""
    import rclpy
    from geometry_msgs.msg import Point
    from rclpy.executors import SingleThreadedExecutor
    from shape_msgs.msg import Mesh, MeshTriangle

    from liver_sim.view.live_view import LiveView
    from msg_defs.point_cloud import nodes_to_pointcloud2
    from msg_defs.skin import skin_mesh_msg
    from msg_defs.topics import TOPICS

    failed = []

    def fail_once(scene, stamp_ns):
        if not failed:
            failed.append(stamp_ns)
            raise RuntimeError("a tick that fails")

    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    view = LiveView(port=0, rate_hz=50.0, on_scene=fail_once, context=context)
    source = rclpy.create_node("view_test_source", context=context)
    try:
        surface = source.create_publisher(TOPICS["surface"].type, TOPICS["surface"].name, TOPICS["surface"].qos)
        nodes = source.create_publisher(TOPICS["nodes"].type, TOPICS["nodes"].name, TOPICS["nodes"].qos)
        executor.add_node(view)
        executor.add_node(source)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()

        def publish_nodes():
            nodes.publish(nodes_to_pointcloud2(LIVER.points, (1, 0), "liver"))
            time.sleep(POLL_S)

        surface.publish(skin_mesh_msg(LIVER.skin, LIVER.points))
        wait_for(lambda: view.scenes >= 5 and view.tick_errors == 1, 30.0, "scenes and the failing tick",
                 between=publish_nodes)
        bad = Mesh(triangles=[MeshTriangle(vertex_indices=[0, 1, 4000])],
                   vertices=[Point(x=0.0, y=0.0, z=0.0), Point(x=0.01, y=0.0, z=0.0)])
        surface.publish(bad)
        wait_for(lambda: view.refused == 1, 30.0, "the bad Mesh refused", between=publish_nodes)
        served = view.scenes
        wait_for(lambda: view.scenes >= served + 10, 30.0, "scenes after the bad Mesh", between=publish_nodes)
        assert view.tick_errors == 1 and view.refused == 1 and view._loop.is_alive()
    finally:
        view.close()
        executor.shutdown()
        view.destroy_node()
        source.destroy_node()
        context.try_shutdown()


def test_the_view_command_refuses_a_public_address_by_name():
    result = subprocess.run([sys.executable, "-m", "liver_sim.cli.main", "view", "--host", "0.0.0.0",
                             "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "--host 0.0.0.0" in result.stderr and "--allow-remote" in result.stderr


def test_the_live_view_serves_the_running_network_to_a_foxglove_client(recorded_demo):
    """The shared `demo --view` on a free port: a Foxglove client sees the three channels, decodes scenes whose skin
    is the default liver's, at 20 scenes a second or more (asked for 40), and the demo leaves the view's picture."""
    assert recorded_demo.view is not None, "the Foxglove client never connected to the view"
    info, channels, received = recorded_demo.view
    scenes = received["/liver/scene"]
    assert len(scenes) > 10, f"scenes received: {len(scenes)}; channels: {sorted(channels)}"
    assert set(VIEW_TOPICS) <= set(channels) and info["subprotocol"] in ("foxglove.sdk.v1", "foxglove.websocket.v1")
    scene_channel = channels["/liver/scene"]
    assert scene_channel["schemaName"] == "foxglove.SceneUpdate" and scene_channel["encoding"] == "protobuf"
    schema = schema_bytes(scene_channel)
    entities = decode_scene(scenes[-1][2], schema)
    assert skin_triangles(entities, schema) == len(LIVER.skin)
    arrivals = np.array([arrival for arrival, _, _ in scenes])
    assert len(scenes) / (arrivals[-1] - arrivals[0] + 1.0 / recorded_demo.view_rate_hz) >= 20.0
    assert received["/liver/forces"] and b"device_command_norm_n" in received["/liver/forces"][-1][2]
    assert (recorded_demo.out / "view.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_live_view_shows_both_tools_their_local_models_and_forces(two_hands_demo):
    from liver_sim.studies.two_hands import HANDS

    assert two_hands_demo.view is not None, "the Foxglove client never connected to the view"
    _, channels, received = two_hands_demo.view
    schema = schema_bytes(channels["/liver/scene"])
    scenes = [decode_scene(data, schema) for _, _, data in received["/liver/scene"]]
    for name in HANDS:
        assert any(scene[f"{name}/tool"].get("spheres") for scene in scenes), name
        assert any(scene[f"{name}/force"].get("arrows") for scene in scenes), name
        assert any(scene[f"{name}/local_model"] for scene in scenes), name
    # each hand's forces, under its name, where the layout's plot reads them (config/foxglove_layout.json)
    forces = json.loads(received["/liver/forces"][-1][2])
    plot = json.loads((config_dir() / "foxglove_layout.json").read_text())["configById"]["Plot!forces"]
    read = [path["value"].split(".")[1:] for path in plot["paths"] if path["value"].startswith("/liver/forces.")]
    for name in HANDS:
        assert [name, "device_command_norm_n"] in read and [name, "physics_force_norm_n"] in read
        assert {"device_command_norm_n", "physics_force_norm_n"} <= set(forces[name])


def mcap_schemas(path) -> dict[str, tuple[str, str, bytes]]:
    """{topic: (schema name, schema encoding, schema data)} of an MCAP file, from its uncompressed Schema (0x03)
    and Channel (0x04) records (MCAP repeats them in the summary section)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89MCAP0\r\n", path
    schemas, channels, i = {}, {}, 8

    def string(at):
        (length,) = struct.unpack_from("<I", data, at)
        return data[at + 4:at + 4 + length], at + 4 + length

    while i + 9 <= len(data):
        opcode, length = data[i], struct.unpack_from("<Q", data, i + 1)[0]
        body = i + 9
        if opcode == 0x03:
            (schema_id,) = struct.unpack_from("<H", data, body)
            name, at = string(body + 2)
            encoding, at = string(at)
            payload, _ = string(at)
            schemas[schema_id] = (name.decode(), encoding.decode(), payload)
        elif opcode == 0x04:
            _, schema_id = struct.unpack_from("<HH", data, body)
            topic, _ = string(body + 4)
            channels[topic.decode()] = schema_id
        i = body + length
        if opcode == 0x02:  # a footer ends the file
            break
    return {topic: schemas[schema_id] for topic, schema_id in channels.items() if schema_id in schemas}


def test_a_recorded_session_carries_schemas_foxglove_decodes(recorded_demo):
    """A bag from `liver-sim record` (MCAP) opens in Foxglove as it is: every channel has a ros2msg schema with
    the definitions of the types it nests (the `MSG:` sections Foxglove reads), so its 3-D panel shows the skin
    marker, the local model and the tool, and its plot the forces (config/foxglove_layout.json)."""
    bags = list(recorded_demo.out.glob("session/*.mcap"))
    assert bags, list(recorded_demo.out.glob("session/*"))
    schemas = mcap_schemas(bags[0])
    assert schemas["/liver/surface"][1] == "ros2msg" and b"MSG: shape_msgs" in schemas["/liver/surface"][2]
    for topic in ("/liver/nodes", "/liver/contact_plane", "/tool/pose", "/phantom/servo_cf", "/liver/tool_wrench",
                  "/diagnostics"):
        name, encoding, definition = schemas[topic]
        assert encoding == "ros2msg", (topic, encoding)
        assert b"MSG: std_msgs/Header" in definition or b"MSG: std_msgs/msg/Header" in definition, topic
    marker = schemas["/liver/contact_plane"][2]
    assert b"geometry_msgs/Pose" in marker and b"MSG: geometry_msgs/Point" in marker.replace(b"/msg/", b"/")


def test_the_loop_bench_reads_the_views_share_and_scene_rate(tmp_path):
    """The bench reads the scene rate from the summary `liver-sim view --summary` writes, not from its output."""
    from liver_sim.bench.loop import VIEW, view_figures

    summary = tmp_path / "view_summary.json"
    summary.write_text('{"scenes": 900, "seconds": 30.1, "scenes_per_s": 29.9, "refused_messages": 0, '
                       '"tick_errors": 0}\n')
    figures = view_figures({VIEW: {"cpu_share_of_one_core": 0.04}}, summary)
    assert figures == {"cpu_share_of_one_core": 0.04, "scenes_per_s": 29.9}
    assert view_figures({}, tmp_path / "absent.json") == {"cpu_share_of_one_core": None, "scenes_per_s": None}
