"""Cutting along the tool path (paper §3.5; P14, R5 of docs/paper.md): the cut follows the path, the mesh stays
sound."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from liver_sim.base.local_model import LocalModel
from liver_sim.mesh import TetMesh
from liver_sim.mesh.landmarks import upper_skin_path
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.mesh.tetmesh import signed_volumes
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tissue.springs import stable_time_step
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse
from liver_sim.physics.topology.cutting import SNAP_FRACTION, Ribbon, cut_along_path, default_blade_direction

from meshes import assert_sound, box_mesh, components, kinetic_energy_j

DOWN = np.array([0.0, 0.0, -1.0])
SLAB_SPACING_M = 0.01
SLAB_TOP_M = 0.03


@pytest.fixture(scope="module")
def slab():
    return box_mesh(6, 4, 3, SLAB_SPACING_M)  # 6 × 4 × 3 cm, top at z = 3 cm


@pytest.fixture(scope="module")
def liver():
    return default_liver()


def mean_edge_m(mesh):
    ends = mesh.points[mesh.edges]
    return float(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).mean())


def snap_tolerance_m(mesh, snap_fraction=SNAP_FRACTION):
    """How far a cut may stray from its path: a node snapped onto the cut lies within snap_fraction of its edge."""
    return snap_fraction * longest_edge_m(mesh)


def area_m2(points, triangles):
    p = points[triangles]
    return 0.5 * float(np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())


def longest_edge_m(mesh):
    ends = mesh.points[mesh.edges]
    return float(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).max())


def on_the_cut(points, path, direction, mesh, tol):
    """The points lie on the path's ribbon (within tol of it) and less than an element beyond its ends."""
    ribbon = Ribbon(path, direction)
    phi, along, _ = ribbon.locate(points)
    reach = longest_edge_m(mesh)
    return bool((np.abs(phi) <= tol).all() and (along >= -reach).all() and (along <= ribbon.length_m + reach).all())


def opened_triangles(change):
    """The new mesh's skin triangles that are not capsule: the faces the cut opened."""
    skin = TetMesh(change.rest_points, change.tets).skin
    capsule = {tuple(sorted(t)) for t in change.capsule_triangles.tolist()}
    return skin[[tuple(sorted(t)) not in capsule for t in skin.tolist()]]


def capsule_border_nodes(change):
    """Nodes of the edges where the capsule meets an opened face: the cut's line on the skin."""
    def edges(triangles):
        return {tuple(sorted(e)) for t in triangles.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}

    return np.unique(np.array(sorted(edges(opened_triangles(change)) & edges(change.capsule_triangles))))


def check_sound(mesh, change):
    """Valid, positively oriented, no orphan nodes, volume kept, every component sound (assert_sound:
    watertight, outward, manifold), capsule area kept, opened faces not capsule, state sources consistent
    with rest points.  Returns the number of components."""
    new = TetMesh.from_arrays(change.rest_points, change.tets)
    assert len(new.points) == len(change.rest_points)  # no orphan node
    volumes = signed_volumes(change.rest_points, change.tets)
    assert volumes.min() >= SNAP_FRACTION ** 3 * mesh.volumes.min() * (1 - 1e-9)
    assert volumes.sum() == pytest.approx(mesh.volume, rel=1e-12)
    assert new.lumped_masses(1000.0).sum() == pytest.approx(mesh.lumped_masses(1000.0).sum(), rel=1e-12)
    count = assert_sound(new)
    skin_keys = {tuple(sorted(t)) for t in new.skin.tolist()}
    assert all(tuple(sorted(t)) in skin_keys for t in change.capsule_triangles.tolist())
    assert area_m2(change.rest_points, change.capsule_triangles) == pytest.approx(area_m2(mesh.points, mesh.skin))
    assert len(opened_triangles(change)) > 0
    assert change.separated_faces > 0
    weights = change.node_weights
    assert np.allclose(weights.sum(axis=1), 1.0) and (weights >= 0).all()
    interpolated = (weights[:, :, None] * mesh.points[change.node_sources]).sum(axis=1)
    assert np.allclose(interpolated, change.rest_points, atol=1e-12)
    return count


def slab_path(points_xy):
    return np.column_stack([points_xy, np.full(len(points_xy), SLAB_TOP_M)])


def test_shallow_slab_cut_follows_an_oblique_path_and_opens_only_the_membrane(slab):
    path = slab_path(np.array([[0.012, 0.013], [0.048, 0.027]]))
    change = cut_along_path(slab.points, slab.tets, slab.points, slab.skin, path, 0.012, DOWN, snap_fraction=0.1)
    assert check_sound(slab, change) == 1
    tol = snap_tolerance_m(slab, 0.1)
    border = capsule_border_nodes(change)
    assert len(border) >= 4
    assert on_the_cut(change.rest_points[border], path, DOWN, slab, tol)
    # the crossed skin triangles were split: most of the cut's skin line runs through new nodes on edges
    on_edges = (change.node_weights[border] > 0).sum(axis=1) == 2
    assert on_edges.sum() > len(border) / 2
    # the opened faces lie on the ribbon: the vertical plane through the path, about its length and depth
    corners = change.rest_points[np.unique(opened_triangles(change))]
    assert on_the_cut(corners, path, DOWN, slab, tol)
    assert corners[:, 2].min() >= SLAB_TOP_M - 0.012 - 1.01 * np.sqrt(3) * SLAB_SPACING_M
    assert corners[:, 2].min() < SLAB_TOP_M - SLAB_SPACING_M / 2


def test_cut_through_the_whole_slab_separates_it_in_two(slab):
    path = slab_path(np.array([[-0.01, 0.0155], [0.03, 0.021], [0.07, 0.0245]]))  # bends, ends outside
    change = cut_along_path(slab.points, slab.tets, slab.points, slab.skin, path, 0.05, DOWN)
    assert check_sound(slab, change) == 2
    count, label = components(change.tets, len(change.rest_points))
    tol = snap_tolerance_m(slab)
    for c in range(count):
        part = change.tets[label[change.tets[:, 0]] == c]
        assert signed_volumes(change.rest_points, part).sum() == pytest.approx(slab.volume / 2, rel=0.1)
    corners = change.rest_points[np.unique(opened_triangles(change))]
    assert on_the_cut(corners, path, DOWN, slab, tol)


def test_shallow_cut_across_the_slab_keeps_it_in_one_piece(slab):
    path = slab_path(np.array([[-0.01, 0.0155], [0.07, 0.0245]]))
    change = cut_along_path(slab.points, slab.tets, slab.points, slab.skin, path, 0.01, DOWN)
    assert check_sound(slab, change) == 1


def test_a_cut_along_existing_faces_opens_them_without_new_nodes(slab):
    # the ribbon is the grid plane y = 2 cm: φ vanishes at its nodes and no edge crosses it
    path = slab_path(np.array([[-0.01, 0.02], [0.07, 0.02]]))
    change = cut_along_path(slab.points, slab.tets, slab.points, slab.skin, path, 0.012, DOWN)
    assert check_sound(slab, change) == 1
    assert (change.node_weights.max(axis=1) == 1.0).all()  # every node is an old one or a copy of one
    corners = change.rest_points[np.unique(opened_triangles(change))]
    assert np.allclose(corners[:, 1], 0.02)


def test_path_missing_the_mesh_changes_nothing(slab, liver):
    above = slab_path(np.array([[0.01, 0.01], [0.05, 0.03]])) + [0.0, 0.0, 0.05]
    assert cut_along_path(slab.points, slab.tets, slab.points, slab.skin, above, 0.01, DOWN) is None
    beside = np.array([[0.3, 0.0, 0.0], [0.35, 0.0, 0.0]])
    assert cut_along_path(liver.points, liver.tets, liver.points, liver.skin, beside, 0.02) is None
    assert cut_along_path(slab.points, slab.tets, slab.points, slab.skin, above[:1], 0.01, DOWN) is None


def test_cut_is_placed_in_the_deformed_frame(slab):
    shift = np.array([0.2, -0.1, 0.05])
    path = slab_path(np.array([[0.012, 0.013], [0.048, 0.027]]))
    at_rest = cut_along_path(slab.points, slab.tets, slab.points, slab.skin, path, 0.012, DOWN)
    moved = cut_along_path(slab.points, slab.tets, slab.points + shift, slab.skin, path + shift, 0.012, DOWN)
    assert np.array_equal(at_rest.tets, moved.tets)
    assert np.allclose(at_rest.rest_points, moved.rest_points)


def liver_top_path(liver, length_m, points=11):
    """A path on the liver's upper skin along x."""
    return upper_skin_path(liver, (-0.06, 0.0), (-0.06 + length_m, 0.0), points)


@pytest.mark.parametrize("depth_layers", [1.0, 2.0])
def test_liver_cut_follows_the_path_on_the_skin(liver, depth_layers):
    edge = mean_edge_m(liver)
    path = liver_top_path(liver, 0.08)
    change = cut_along_path(liver.points, liver.tets, liver.points, liver.skin, path, depth_layers * edge)
    check_sound(liver, change)
    tol = snap_tolerance_m(liver)
    border = capsule_border_nodes(change)
    assert len(border) >= 3
    # the cut's line on the skin and every opened corner lie on the ribbon: the path swept along the blade
    d = default_blade_direction(liver.points, liver.tets, path)
    assert on_the_cut(change.rest_points[border], path, d, liver, tol)
    corners = change.rest_points[np.unique(opened_triangles(change))]
    assert on_the_cut(corners, path, d, liver, tol)
    depth = (corners - path.mean(axis=0)) @ d
    assert depth.max() <= depth_layers * edge + 2 * edge


def test_deeper_liver_cut_opens_more(liver):
    edge = mean_edge_m(liver)
    path = liver_top_path(liver, 0.08)
    shallow = cut_along_path(liver.points, liver.tets, liver.points, liver.skin, path, edge)
    deep = cut_along_path(liver.points, liver.tets, liver.points, liver.skin, path, 3 * edge)
    d = default_blade_direction(liver.points, liver.tets, path)
    reach = [(c.rest_points[np.unique(opened_triangles(c))] @ d).max() for c in (shallow, deep)]
    assert deep.separated_faces > shallow.separated_faces
    assert reach[1] > reach[0] + edge / 2
    assert components(deep.tets, len(deep.rest_points))[0] == 1


def test_cut_liver_model_keeps_its_mass_and_simulates_stably(liver):
    # a cut makes shorter springs, so the stability bound drops: an explicit integrator's model raises its
    # substeps to stay below it
    model = LiverModel(liver, ModelParams(integrator="symplectic_euler"))
    edge = mean_edge_m(liver)
    mass_kg = model.structure.masses_kg.sum()
    substeps = model.structure.params.substeps
    assert model.cut(liver_top_path(liver, 0.08), 2 * edge)
    assert model.structure.version == 1
    assert model.structure.masses_kg.sum() == pytest.approx(mass_kg, rel=1e-12)
    assert np.allclose(model.state.positions, model.structure.mesh.points)
    assert model.structure.params.dt_s <= model.structure.stable_dt_s and model.structure.params.substeps >= substeps
    model.state.velocities += np.random.default_rng(0).normal(scale=0.05, size=model.state.velocities.shape)
    assert all(model.step_frame().divergence is None for _ in range(30))
    assert kinetic_energy_j(model) < 0.5 * float((model.structure.masses_kg * 0.05 ** 2 * 3).sum())


def test_the_stability_estimate_after_each_cut_is_not_above_the_exact_bound(liver):
    model = LiverModel(liver, ModelParams(integrator="symplectic_euler"))
    edge = mean_edge_m(liver)
    for path in (liver_top_path(liver, 0.08), upper_skin_path(liver, (-0.03, -0.04), (-0.03, 0.04))):
        assert model.cut(path, 2 * edge)
        p = model.structure.params
        exact = stable_time_step(model.structure.springs, model.structure.masses_kg, p.environment_damping_per_s,
                                 p.integrator, model.structure.mesh.points)
        assert model.structure.stable_dt_s <= 1.02 * exact
        assert p.dt_s <= exact
    model.state.velocities += np.random.default_rng(1).normal(scale=0.05, size=model.state.velocities.shape)
    assert all(model.step_frame().divergence is None for _ in range(30))


def random_stroke(model, rng, previous):
    """A blade path (P, 3) in the deformed frame: a chord between two skin nodes (through nodes, along the
    mesh), a diagonal on the upper skin, a stroke of 0.3 mm to 3 cm from a skin node, a 10–40 cm stroke
    that leaves the liver, a wiggly polyline, or a stroke across the middle of the `previous` path."""
    x = model.state.positions
    skin = model.structure.mesh.skin_nodes
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    kind = rng.integers(6)
    if kind == 0:
        return np.linspace(*x[rng.choice(skin, 2, replace=False)], rng.integers(2, 12))
    if kind == 1:
        low, high = model.structure.mesh.bounds[:, :2] * 0.8
        try:
            return upper_skin_path(model.structure.mesh, rng.uniform(low, high), rng.uniform(low, high),
                                   rng.integers(2, 15))
        except ValueError:  # a point not above the mesh: a straight line over it
            kind = 3
    if kind == 2:
        return x[rng.choice(skin)] + np.outer(np.linspace(0.0, 10 ** rng.uniform(-3.5, -1.5), rng.integers(2, 6)),
                                              direction)
    if kind == 3:
        return x[rng.choice(skin)] + np.outer(np.linspace(-0.5, 0.5, rng.integers(2, 30)) * rng.uniform(0.1, 0.4),
                                              direction)
    if kind == 4:
        return x[rng.choice(skin)] + np.cumsum(rng.normal(scale=0.01, size=(rng.integers(2, 10), 3)), axis=0)
    middle = previous[len(previous) // 2]
    return middle + np.outer(np.linspace(-0.03, 0.03, rng.integers(2, 12)), direction)


def stroke(model, path):
    """The tool in cut mode in contact along `path`, then off the surface (LiverModel.after_frame): (True when the
    mesh changed, why the cut failed)."""
    for point in path:
        model.after_frame(LocalModel("plane", True, point, [0.0, 0.0, 1.0], point, 0.0, 0.001, True))
    changes, failures = model.after_frame(LocalModel.invalid())
    return changes == ["cut"], failures


def test_many_random_cuts_never_raise_and_keep_the_mesh_sound(liver):
    # crossing strokes, strokes along mesh edges, very short and very long ones, some on a deformed liver;
    # this seed makes strokes whose ribbon meets the mesh at nodes only (it raised IndexError)
    rng = np.random.default_rng(13)
    use = ToolUse("cut")
    model = LiverModel(liver, ModelParams(), Tool(use=use))
    mass_kg = model.structure.masses_kg.sum()
    previous = liver_top_path(liver, 0.08)
    changes = 0
    for k in range(60):
        if k % 4 == 3:  # deform the liver by a small random linear map about its centre
            centre = model.state.positions.mean(axis=0)
            linear = np.eye(3) + rng.normal(scale=0.03, size=(3, 3))
            model.state.positions = centre + (model.state.positions - centre) @ linear
        use.cut_depth_m = 10 ** rng.uniform(-3.3, -1.3)
        path = random_stroke(model, rng, previous)
        version = model.structure.version
        changed, failures = stroke(model, path)
        assert not failures, failures
        assert model.structure.version == version + changed
        if changed:
            changes += 1
            previous = path
            assert_sound(model.structure.mesh)
            assert len(model.state.positions) == len(model.structure.mesh.points) == len(model.structure.masses_kg)
        assert np.isfinite(model.state.positions).all() and np.isfinite(model.state.velocities).all()
        assert model.structure.masses_kg.sum() == pytest.approx(mass_kg, rel=1e-9)
    assert changes >= 30
    assert model.structure.params.dt_s <= model.structure.stable_dt_s
    model.state.positions = model.structure.mesh.points.copy()
    model.state.velocities += rng.normal(scale=0.01, size=model.state.velocities.shape)
    assert all(model.step_frame().divergence is None for _ in range(3))
    assert np.isfinite(model.state.positions).all()


def test_repeated_cuts_keep_one_implicit_step_per_frame(liver):
    # the implicit integrator has no stability bound: short springs and light nodes a cut makes change nothing
    model = LiverModel(liver)
    edge = mean_edge_m(liver)
    paths = (liver_top_path(liver, 0.08), upper_skin_path(liver, (-0.03, -0.04), (-0.03, 0.04)),
             upper_skin_path(liver, (0.02, -0.03), (0.05, 0.03)))
    rng = np.random.default_rng(2)
    for version, path in enumerate(paths, start=1):
        assert model.cut(path, 2 * edge)
        assert model.structure.version == version and model.structure.params.substeps == 1
        model.state.velocities += rng.normal(scale=0.05, size=model.state.velocities.shape)
        assert all(model.step_frame().divergence is None for _ in range(30))
    assert model.divergences == 0 and np.isfinite(model.state.positions).all()
    assert kinetic_energy_j(model) < 0.5 * float((model.structure.masses_kg * 0.05 ** 2 * 3).sum())


#: A fresh interpreter builds the physics node's model (tearing on), then cuts, tears and steps it; it prints the
#: numba kernels that gained a compiled version after the build's warm-up.
COMPILES_AFTER_WARM_UP = """
import importlib, json, pkgutil
import numba, numpy as np
import liver_sim.physics as physics
from liver_sim.physics.parameters import PhysicsParameters, build_model
from liver_sim.physics.topology.tearing import tear
from test_cutting import liver_top_path, mean_edge_m

def versions():
    modules = [importlib.import_module(m.name)  # every room's modules, not only those at physics' root
               for m in pkgutil.walk_packages(physics.__path__, "liver_sim.physics.")]
    return {f"{m.__name__}.{name}": len(f.signatures) for m in modules for name, f in vars(m).items()
            if isinstance(f, numba.core.registry.CPUDispatcher)}

model = build_model(PhysicsParameters.defaults().replace(tearing=True))
before = versions()
assert model.cut(liver_top_path(model.structure.mesh, 0.08), 2 * mean_edge_m(model.structure.mesh))
model.step_frame()
mesh = model.structure.mesh
change = tear(mesh.points, mesh.tets, model.state.positions * [1.5, 1.0, 1.0], model.structure.capsule_triangles, 0.15,
              0.2)
model.apply(change)
model.step_frame()
print(json.dumps({name: n for name, n in versions().items() if n != before.get(name)}))
"""


def test_after_the_warm_up_a_cut_and_a_tear_compile_nothing():
    """The model's warm-up compiles what a frame, a tear and a cut run: a kernel compiled inside the 150 Hz loop
    stalls it for seconds. In a fresh interpreter, so that kernels other tests compiled do not count."""
    support = Path(__file__).resolve().parents[3] / "support"  # test/support
    result = subprocess.run([sys.executable, "-c", COMPILES_AFTER_WARM_UP], cwd=Path(__file__).parent,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (
                                str(support), os.environ.get("PYTHONPATH"))))},
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {}
