"""load_mesh / write_mesh: every readable format, every refused input, the tagged round trip."""
import math
import sys

import meshio
import numpy as np
import pytest
import trimesh

from liver_sim.mesh import io as mesh_io
from liver_sim.mesh.io import load_mesh, write_mesh
from liver_sim.mesh.tetmesh import MeshError, TetMesh, signed_volumes

from meshes import CUBE_EDGE_M, cube_arrays, inverted_cube_arrays, write_sphere_surface

EDGE = CUBE_EDGE_M
SPHERE_RADIUS = 0.05  # m


def write_meshio(path, points, cells, **kwargs):
    meshio.write(path, meshio.Mesh(points, cells), **kwargs)
    return path


def assert_refused(path, defect, **kwargs):
    with pytest.raises(MeshError) as caught:
        load_mesh(path, **kwargs)
    message = str(caught.value)
    assert str(path) in message
    assert defect.lower() in message.lower()


def sphere_surface(tmp_path, suffix, inverted=False):
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=SPHERE_RADIUS)
    if inverted:
        sphere.invert()
    path = tmp_path / f"sphere{suffix}"
    sphere.export(path)
    return path


@pytest.mark.parametrize("name, other_cells, options", [
    ("cube22.msh", True, {"file_format": "gmsh22", "binary": False}),
    ("cube22b.msh", True, {"file_format": "gmsh22", "binary": True}),
    ("cube41.msh", False, {"file_format": "gmsh", "binary": False}),  # 4.1 needs entities for 2 types
    ("cube41b.msh", False, {"file_format": "gmsh", "binary": True}),
    ("cube.vtu", True, {}),
    ("cube.vtk", True, {}),
    ("cube.mesh", True, {}),
])
def test_volume_formats_load_and_reorient_the_inverted_tet(tmp_path, name, other_cells, options):
    points, tets = inverted_cube_arrays()
    triangles = [("triangle", np.array([[0, 2, 1], [1, 2, 3]]))] if other_cells else []  # ignored
    path = write_meshio(tmp_path / name, points, [*triangles, ("tetra", tets)], **options)
    mesh = load_mesh(path)
    assert mesh.source == str(path)
    np.testing.assert_array_equal(mesh.points, points)
    np.testing.assert_array_equal(np.sort(mesh.tets, axis=1), np.sort(tets, axis=1))
    assert signed_volumes(points, tets[:1])[0] < 0
    assert (signed_volumes(mesh.points, mesh.tets) > 0).all()
    assert mesh.volume == pytest.approx(EDGE ** 3)
    assert len(mesh.skin) == 12 and mesh.watertight


def test_gmsh_v1_reader_maps_node_labels(tmp_path):
    points, tets = cube_arrays()
    labels = np.array([70, 10, 30, 80, 20, 50, 40, 60])  # node i is written as labels[i]
    order = [3, 1, 7, 0, 2, 6, 4, 5]  # and in a shuffled order
    lines = ["$NOD", "8"] + [f"{labels[i]} {points[i][0]} {points[i][1]} {points[i][2]}" for i in order]
    lines += ["$ENDNOD", "$ELM", "8", "1 15 1 1 1 70", "2 2 1 1 3 70 10 30"]
    lines += [f"{k + 3} 4 2 3 4 " + " ".join(str(labels[n]) for n in tet) for k, tet in enumerate(tets)]
    lines += ["$ENDELM", ""]
    path = tmp_path / "cube_v1.msh"
    path.write_text("\n".join(lines))
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.points, points[order])
    inverse = np.argsort(order)
    np.testing.assert_array_equal(mesh.tets, inverse[tets])
    assert mesh.volume == pytest.approx(EDGE ** 3)


def test_gmsh_v1_reader_refuses_undefined_node(tmp_path):
    path = tmp_path / "broken_v1.msh"
    path.write_text("$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n"
                    "$ELM\n1\n1 4 1 1 4 1 2 3 9\n$ENDELM\n")
    assert_refused(path, "undefined node 9")


def test_gmsh_v1_reader_refuses_wrong_count(tmp_path):
    path = tmp_path / "short_v1.msh"
    path.write_text("$NOD\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n"
                    "$ELM\n1\n1 4 1 1 4 1 2 3 4\n$ENDELM\n")
    assert_refused(path, "$NOD announces 5 entries")


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".off"])
def test_closed_surface_becomes_tets(tmp_path, suffix):
    path = sphere_surface(tmp_path, suffix)
    mesh = load_mesh(path, target_tets=800)
    assert mesh.source == str(path)
    assert mesh.watertight
    assert mesh.volume == pytest.approx(4 / 3 * math.pi * SPHERE_RADIUS ** 3, rel=0.08)
    assert np.all(np.linalg.norm(mesh.points, axis=1) < SPHERE_RADIUS * 1.02)


def test_inverted_surface_winding_is_fixed(tmp_path):
    reference = load_mesh(sphere_surface(tmp_path, ".stl"), target_tets=500)
    inverted = load_mesh(sphere_surface(tmp_path, ".off", inverted=True), target_tets=500)
    assert inverted.volume == pytest.approx(reference.volume, rel=1e-6)


def test_refuses_missing_file(tmp_path):
    assert_refused(tmp_path / "absent.msh", "no such file")


def test_refuses_unknown_extension(tmp_path):
    path = tmp_path / "cube.xyz"
    path.write_text("8 nodes")
    assert_refused(path, "unsupported file format '.xyz'")


@pytest.mark.parametrize("name", ["garbage.msh", "garbage.vtu", "garbage.vtk", "garbage.mesh",
                                  "garbage.stl", "garbage.obj", "garbage.off", "garbage.ply"])
def test_refuses_garbage_bytes(tmp_path, name, capfd):
    path = tmp_path / name
    path.write_bytes(np.random.default_rng(7).integers(0, 256, 700, dtype=np.uint8).tobytes())
    assert_refused(path, "unreadable")
    assert capfd.readouterr().out == ""


def test_reader_exit_becomes_mesh_error(tmp_path, monkeypatch):
    def exiting_reader(filename):
        sys.exit(1)

    monkeypatch.setitem(mesh_io.VOLUME_READERS, ".vtu", ("VTK XML", exiting_reader))
    points, tets = cube_arrays()
    path = write_meshio(tmp_path / "cube.vtu", points, [("tetra", tets)])
    assert_refused(path, "unreadable VTK XML file")


def test_refuses_mesh_without_tets(tmp_path):
    points, _ = cube_arrays()
    path = write_meshio(tmp_path / "skin_only.vtu", points, [("triangle", np.array([[0, 1, 2]]))])
    assert_refused(path, "no tetrahedra (cell types found: triangle)")


def test_refuses_mesh_without_cells(tmp_path):
    path = write_meshio(tmp_path / "nodes_only.msh", cube_arrays()[0], [], file_format="gmsh22", binary=False)
    assert_refused(path, "empty mesh: no cells")


@pytest.mark.parametrize("name", ["empty.msh", "empty.vtu", "empty.stl"])
def test_refuses_empty_file(tmp_path, name):
    path = tmp_path / name
    path.touch()
    assert_refused(path, "empty file")


def test_refuses_empty_surface(tmp_path):
    path = tmp_path / "empty.stl"
    path.write_text("solid empty\nendsolid empty\n")
    assert_refused(path, "empty surface")


def test_refuses_nan_node(tmp_path):
    points, tets = cube_arrays()
    points[5, 2] = np.nan
    path = write_meshio(tmp_path / "nan.vtu", points, [("tetra", tets)])
    assert_refused(path, "NaN")


def test_refuses_nan_surface_vertex(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=SPHERE_RADIUS)
    vertices = sphere.vertices.copy()
    vertices[3] = np.nan
    path = tmp_path / "nan.obj"
    trimesh.Trimesh(vertices, sphere.faces, process=False).export(path)
    assert_refused(path, "NaN")


def test_refuses_open_surface(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=SPHERE_RADIUS)
    path = tmp_path / "open.stl"
    trimesh.Trimesh(sphere.vertices, sphere.faces[3:], process=False).export(path)
    assert_refused(path, "open surface, not watertight")


def test_refuses_degenerate_surface(tmp_path):
    # A closed tetrahedron surface whose edge 0-1 carries a midpoint, closed by a zero-area triangle.
    vertices = 0.1 * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0, 0]])
    faces = [[0, 4, 2], [4, 1, 2], [1, 0, 3], [0, 1, 4], [0, 3, 2], [1, 2, 3]]
    path = tmp_path / "flat.off"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    assert_refused(path, "1 zero-area triangles")


def test_refuses_degenerate_tet(tmp_path):
    points = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0], [0, 0, 0.1]])
    tets = np.array([[0, 1, 2, 4], [0, 1, 2, 3]])  # the second is flat
    path = write_meshio(tmp_path / "flat.vtk", points, [("tetra", tets)])
    assert_refused(path, "degenerate (zero-volume) tetrahedra")


def test_refuses_folded_tets(tmp_path):
    points = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1], [0.02, 0.02, 0.05]])
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4]])  # both on the same side of face 0-1-2
    path = write_meshio(tmp_path / "folded.msh", points, [("tetra", tets)], file_format="gmsh22", binary=False)
    assert_refused(path, "inverted or folded elements beyond repair")


@pytest.mark.parametrize("factor, suggested", [(100.0, "0.01"), (1000.0, "0.001"), (0.1, "10")])
def test_a_mesh_not_the_size_of_an_organ_is_refused_with_its_size_and_the_scale_to_use(tmp_path, factor, suggested):
    points, tets = cube_arrays()  # 0.1 m: written in centimetres (×100), millimetres (×1000) or too small (×0.1)
    path = write_meshio(tmp_path / "unitless.msh", points * factor, [("tetra", tets)], file_format="gmsh22",
                        binary=False)
    side = EDGE * factor
    assert_refused(path, f"implausible size for an organ: {side:g} x {side:g} x {side:g} m across, "
                         f"{side ** 3:.4g} m^3")
    with pytest.raises(MeshError) as caught:
        load_mesh(path)
    assert f"--scale {suggested} " in str(caught.value) and "mesh_scale" in str(caught.value)
    mesh = load_mesh(path, scale=1.0 / factor)
    np.testing.assert_allclose(mesh.points, points, rtol=1e-12, atol=1e-15)
    assert mesh.volume == pytest.approx(EDGE ** 3)


def test_the_suggested_scale_loads_a_centimetre_surface_at_its_size(tmp_path):
    path = write_sphere_surface(tmp_path / "sphere_cm.stl", SPHERE_RADIUS * 100)
    with pytest.raises(MeshError, match=r"sphere_cm.stl: implausible size for an organ: (9|10)[.0-9]* x .* m across, "
                                        r"5\d\d(\.\d+)? m\^3 .*--scale 0\.01 "):
        load_mesh(path, target_tets=500)
    mesh = load_mesh(path, target_tets=500, scale=0.01)
    assert mesh.source == str(path)
    assert mesh.volume == pytest.approx(4 / 3 * math.pi * SPHERE_RADIUS ** 3, rel=0.08)
    assert np.ptp(mesh.points, axis=0) == pytest.approx([2 * SPHERE_RADIUS] * 3, rel=0.05)


def test_a_scale_that_still_leaves_an_implausible_size_says_so(tmp_path):
    points, tets = cube_arrays()
    path = write_meshio(tmp_path / "mm.vtu", points * 1000, [("tetra", tets)])
    assert_refused(path, "after scaling by 0.01", scale=0.01)  # millimetres taken for centimetres: 1 m across
    with pytest.raises(MeshError, match=r"--scale 0\.001 "):
        load_mesh(path, scale=0.01)


@pytest.mark.parametrize("scale", [0.0, -0.01, math.nan, math.inf])
def test_a_scale_that_is_not_a_positive_factor_is_refused(tmp_path, scale):
    points, tets = cube_arrays()
    assert_refused(write_meshio(tmp_path / "cube.vtu", points, [("tetra", tets)]), f"scale {scale!r}", scale=scale)


@pytest.mark.parametrize("suffix", [".msh", ".vtu"])
def test_write_then_load_round_trip_keeps_hash_and_tags_skin(tmp_path, suffix):
    mesh = TetMesh.from_arrays(*inverted_cube_arrays(), source="cube")
    path = write_mesh(mesh, tmp_path / f"out{suffix}")
    again = load_mesh(path)
    assert again.sha256 == mesh.sha256
    raw = meshio.read(path)
    tags = raw.cell_data["gmsh:physical" if suffix == ".msh" else "region"]
    regions = {block.type: (len(block.data), set(np.unique(tag))) for block, tag in zip(raw.cells, tags)}
    assert regions == {"triangle": (len(mesh.skin), {1}), "tetra": (len(mesh.tets), {2})}


def test_msh_output_is_gmsh22_ascii_with_named_groups(tmp_path):
    path = write_mesh(TetMesh.from_arrays(*cube_arrays()), tmp_path / "named.msh")
    text = path.read_text()
    assert text.startswith("$MeshFormat\n2.2 0 8\n")
    assert '2 1 "capsule"' in text and '3 2 "parenchyma"' in text


def test_write_refuses_unknown_extension_and_unwritable_path(tmp_path):
    mesh = TetMesh.from_arrays(*cube_arrays())
    with pytest.raises(MeshError, match=r"out\.stl: unsupported output format"):
        write_mesh(mesh, tmp_path / "out.stl")
    with pytest.raises(MeshError, match="cannot write"):
        write_mesh(mesh, tmp_path / "no" / "such" / "dir.msh")
