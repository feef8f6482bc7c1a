"""A Scene (liver_sim.view.scene) as the Foxglove SDK's foxglove.SceneUpdate, without ROS: what `liver-sim view`
logs on its `/liver/scene` channel (liver_sim.view.live_view)."""
from __future__ import annotations

import numpy as np
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

from liver_sim.view.scene import (
    FORCE_COLOUR,
    LIPS_COLOUR,
    MODEL_COLOUR,
    TOOL_COLOUR,
    Scene,
    SceneTool,
    force_arrow,
    plane_patch,
)


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


def scene_update(scene: Scene, stamp_ns: int, frame_id: str = "liver") -> SceneUpdate:
    """The foxglove.SceneUpdate of `scene`: entities `skin` (the node points with their colours, indexed by the
    skin triangles), per tool `tool`, `local_model`, `force` (after 'NAME/' for a named tool: `left/tool`, …),
    `lips` (an absent one is sent empty, so that the app removes what it showed)."""
    stamp = Timestamp(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)

    def entity(name, **primitives):
        return SceneEntity(timestamp=stamp, frame_id=frame_id, id=name, **primitives)

    skin = TriangleListPrimitive(pose=_pose(), points=[_point(p) for p in scene.points],
                                 colors=[_colour(c) for c in scene.colours], indices=scene.skin.ravel().tolist())
    entities = [entity("skin", triangles=[skin])]
    for tool in scene.tools:
        entities += tool_entities(tool, entity)
    lines = []
    if len(scene.lips):
        lines = [LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose(), thickness=2.0, scale_invariant=True,
                               points=[_point(p) for p in scene.lips.reshape(-1, 3)], color=_colour(LIPS_COLOUR))]
    entities.append(entity("lips", lines=lines))
    return SceneUpdate(entities=entities)


def tool_entities(tool: SceneTool, entity) -> list[SceneEntity]:
    """A tool's entities `tool` (its sphere), `local_model` (a plane patch or a sphere), `force` (an arrow), after
    'NAME/' for a named tool; `entity(id, **primitives)` makes one."""
    prefix = f"{tool.name}/" if tool.name else ""
    sphere = []
    if tool.tool_tip_m is not None:
        d = 2.0 * tool.tool_radius_m
        sphere = [SpherePrimitive(pose=_pose(tool.tool_tip_m), size=Vector3(x=d, y=d, z=d),
                                  color=_colour(TOOL_COLOUR))]
    model = tool.local_model
    patch, ball = [], []
    if model is not None and model.kind == "plane":
        corners = plane_patch(model).reshape(-1, 3)
        patch = [TriangleListPrimitive(pose=_pose(), points=[_point(p) for p in corners], color=_colour(MODEL_COLOUR))]
    elif model is not None:
        d = 2.0 * model.radius_m
        ball = [SpherePrimitive(pose=_pose(model.centre), size=Vector3(x=d, y=d, z=d), color=_colour(MODEL_COLOUR))]
    arrow = force_arrow(tool)
    arrows = []
    if arrow is not None:
        start, end = arrow
        length = float(np.linalg.norm(end - start))
        arrows = [ArrowPrimitive(pose=_pose(start, arrow_orientation(end - start)), shaft_length=0.8 * length,
                                 shaft_diameter=0.002, head_length=0.2 * length, head_diameter=0.005,
                                 color=_colour(FORCE_COLOUR))]
    return [entity(f"{prefix}tool", spheres=sphere), entity(f"{prefix}local_model", triangles=patch, spheres=ball),
            entity(f"{prefix}force", arrows=arrows)]
