"""Contact of the rigid tools with the skin triangles (Eq. 3 at the nearest surface points, barycentric
weights) on the whole model: never sinking between nodes, sliding without losing the force, mesh-independent (the
kernels' continuity over edges and corners: contact/test_kernels.py)."""
import numpy as np
import pytest

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import build_liver
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.structure import default_fixed_nodes
from liver_sim.physics.tools.tool import Tool

FRAME_RATE_HZ = 150.0
UP = np.array([0.0, 0.0, 1.0])
#: Tools pressed tip first (a capsule standing on its tip, a box on a face).
TOOLS = {"sphere": ToolShape(), "capsule": ToolShape("capsule", length_m=0.05),
         "box": ToolShape("box", half_extents_m=(0.01, 0.01, 0.01))}


def surface_height(mesh, xy):
    """z (m) of the highest skin triangle above the point xy of the rest mesh (a vertical ray)."""
    corners = mesh.points[mesh.skin]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        u = ((xy[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (xy[1] - a[:, 1])) / det
        v = ((b[:, 0] - a[:, 0]) * (xy[1] - a[:, 1]) - (xy[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    inside = (u >= 0) & (v >= 0) & (u + v <= 1) & (det != 0)
    z = a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (c[:, 2] - a[:, 2])
    return float(z[inside].max())


def tool_bottom_m(shape):
    """How far below the tip the tool reaches along −z (pressed tip first)."""
    return shape.half_extents_m[2] if shape.kind == "box" else shape.radius_m


def press_forces(model, xy, depths_m, frames_per_mm=15):
    """|force on the tool| (N) at each depth (m) below the rest surface at xy, pressing slowly (1 mm per
    `frames_per_mm` frames) and settling 30 frames at each depth."""
    top = surface_height(model.structure.mesh, xy)
    bottom = tool_bottom_m(model.tool.shape)
    forces, depth = [], 0.0
    model.reset()
    for target in depths_m:
        steps = max(int(round((target - depth) * 1000 * frames_per_mm)), 1)
        for d in np.linspace(depth, target, steps + 1)[1:]:
            model.step_frame(ToolPose(np.array([xy[0], xy[1], top + bottom - d])))
        for _ in range(30):
            result = model.step_frame(ToolPose(np.array([xy[0], xy[1], top + bottom - target])))
        assert result.divergence is None
        forces.append(float(np.linalg.norm(result.tool_force_n)))
        depth = target
    return np.array(forces)


def places(mesh):
    """The dome's top node, the centroid of a skin triangle beside it and the midpoint of one of its edges
    (between nodes)."""
    anchor = press_anchor(mesh)
    skin = mesh.skin
    node = int(np.argmax(mesh.points[:, 2] * np.isin(np.arange(len(mesh.points)), skin.ravel())))
    triangle = skin[np.flatnonzero((skin == node).any(axis=1))[0]]
    corners = mesh.points[triangle]
    return {"node": anchor[:2], "triangle": corners.mean(axis=0)[:2],
            "edge": ((corners[0] + corners[1]) / 2)[:2]}


@pytest.mark.parametrize("integrator", ["implicit_euler", "symplectic_euler"])
def test_pressing_deeper_never_lowers_the_force_even_between_nodes(liver, integrator):
    params = ModelParams(integrator=integrator, substeps=1 if integrator == "implicit_euler" else 72)
    model = LiverModel(liver, params)
    for name, xy in places(liver).items():
        forces = press_forces(model, xy, [0.002, 0.004, 0.006, 0.008, 0.010])
        assert forces[0] > 0.0, name
        assert (np.diff(forces) > 0.0).all(), (name, forces)


@pytest.mark.parametrize("kind", ["capsule", "box"])
def test_capsule_and_box_pressed_deeper_push_harder(liver, kind):
    model = LiverModel(liver, ModelParams(), Tool(TOOLS[kind]))
    for name, xy in places(liver).items():
        forces = press_forces(model, xy, [0.002, 0.005, 0.008])
        assert forces[0] > 0.0 and (np.diff(forces) > 0.0).all(), (name, forces)


@pytest.mark.parametrize("kind", ["sphere", "capsule", "box"])
def test_sliding_in_contact_never_drops_the_force_to_zero(liver, kind):
    shape = TOOLS[kind]
    model = LiverModel(liver, ModelParams(), Tool(shape))
    anchor = press_anchor(liver)
    top = surface_height(liver, anchor[:2])
    start = np.array([anchor[0] - 0.015, anchor[1], top + tool_bottom_m(shape) - 0.008])
    for d in np.linspace(0.0, 0.008, 120):  # press 8 mm, slowly
        model.step_frame(ToolPose(start + [0.0, 0.0, 0.008 - d]))
    slide = [np.linalg.norm(model.step_frame(ToolPose(start + [s, 0.0, 0.0])).tool_force_n)
             for s in np.linspace(0.0, 0.03, 226)]  # 3 cm in 1.5 s (the demo's slide)
    assert min(slide) > 0.2 * np.median(slide) > 0.0


def test_the_same_indentation_on_a_finer_liver_gives_the_same_force(liver):
    """A 5 mm press with the sphere at the same place on the default liver (~1.2k tets) and a ~10k-tet one,
    both held at the same place (the nodes within 15 mm of the default support's centre; one central tet
    is a smaller support on the finer mesh, about which it pivots more freely): forces within 25 % (node
    contact gave 0.4×–4.3×)."""
    centre = liver.points[default_fixed_nodes(liver)].mean(axis=0)
    forces = []
    for mesh in (liver, build_liver(10_000)):
        held = np.flatnonzero(np.linalg.norm(mesh.points - centre, axis=1) < 0.015)
        model = LiverModel(mesh, ModelParams(fixed_nodes=held))
        forces.append(press_forces(model, places(liver)["node"], [0.005])[0])
    assert forces[1] == pytest.approx(forces[0], rel=0.25)
