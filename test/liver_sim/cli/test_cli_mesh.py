"""`liver-sim mesh info|build`: output consistent with the file, refusals as exit 2 with a reason."""
import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from liver_sim.cli.main import main
from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.liver_shape import default_liver

REPO = Path(__file__).resolve().parents[3]
SIDE, HEIGHT = 0.06, 0.04  # m: right-triangle legs and height of the prism fixture


PRISM_POINTS = np.array([[0, 0, 0], [SIDE, 0, 0], [0, SIDE, 0], [0, 0, HEIGHT], [SIDE, 0, HEIGHT], [0, SIDE, HEIGHT]])
PRISM_TETS = np.array([[0, 1, 2, 5], [0, 1, 5, 4], [0, 4, 5, 3]])


@pytest.fixture
def prism(tmp_path):
    """A right triangular prism (6 nodes, 3 tets, 8 skin triangles) written by meshio as .vtu."""
    path = tmp_path / "prism.vtu"
    meshio.write(path, meshio.Mesh(PRISM_POINTS, [("tetra", PRISM_TETS)]))
    return path


@pytest.fixture
def prism_cm(tmp_path):
    """The prism in centimetres (6 x 6 x 4 units, unitless), as Gmsh 2.2 from another simulator."""
    path = tmp_path / "prism_cm.msh"
    tags = [np.ones(len(PRISM_TETS), dtype=int)]
    meshio.write(path, meshio.Mesh(PRISM_POINTS * 100, [("tetra", PRISM_TETS)],
                                   cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags}),
                 file_format="gmsh22", binary=False)
    return path


@pytest.fixture
def garbage(tmp_path):
    path = tmp_path / "garbage.msh"
    path.write_bytes(bytes(range(256)) * 3)
    return path


def run_json(capsys, *args):
    assert main(["mesh", "info", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def assert_refused(capsys, argv, reason):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"liver-sim: error: {reason}")
    assert "Traceback" not in captured.err


def test_info_json_matches_the_file(capsys, prism):
    info = run_json(capsys, prism)
    mesh = load_mesh(prism)
    assert info["source"] == str(prism)
    assert (info["nodes"], info["tetrahedra"], info["skin_triangles"]) == (6, 3, 8)
    assert info["volume_m3"] == pytest.approx(SIDE * SIDE / 2 * HEIGHT)
    assert info["volume_l"] == pytest.approx(info["volume_m3"] * 1e3)
    assert info["size_m"] == pytest.approx([SIDE, SIDE, HEIGHT])
    assert info["min_dihedral_deg"] == pytest.approx(mesh.dihedral_angles_deg.min())
    assert info["watertight"] is True
    assert info["sha256"] == mesh.sha256


def test_info_text_is_human_readable(capsys, prism):
    assert main(["mesh", "info", str(prism)]) == 0
    out = capsys.readouterr().out
    assert "tetrahedra      3\n" in out
    assert f"volume          {SIDE * SIDE / 2 * HEIGHT:.6g} m^3 (0.072 L)" in out
    assert "watertight      yes" in out
    assert load_mesh(prism).sha256 in out


def test_info_without_path_describes_the_default_liver(capsys):
    info = run_json(capsys)
    liver = default_liver()
    assert (info["tetrahedra"], info["sha256"]) == (len(liver.tets), liver.sha256)


def test_build_then_info_gives_the_same_mesh(capsys, prism, tmp_path):
    out = tmp_path / "x.msh"
    assert main(["mesh", "build", str(prism), "--out", str(out)]) == 0
    assert f"wrote {out}: 6 nodes, 3 tetrahedra" in capsys.readouterr().out
    info = run_json(capsys, out)
    assert (info["tetrahedra"], info["sha256"]) == (3, load_mesh(prism).sha256)


def test_build_default_liver_to_vtu(capsys, tmp_path):
    out = tmp_path / "liver.vtu"
    assert main(["mesh", "build", "--out", str(out)]) == 0
    capsys.readouterr()
    assert run_json(capsys, out)["tetrahedra"] == len(default_liver().tets)


def test_bad_file_exits_2_with_the_reason(capsys, garbage):
    assert_refused(capsys, ["mesh", "info", str(garbage)], f"{garbage}: unreadable Gmsh file")


def test_missing_file_exits_2(capsys, tmp_path):
    missing = tmp_path / "absent.vtu"
    assert_refused(capsys, ["mesh", "build", str(missing), "--out", str(tmp_path / "o.msh")],
                   f"{missing}: no such file")


def test_build_refuses_unknown_output_format(capsys, prism, tmp_path):
    out = tmp_path / "x.stl"
    assert_refused(capsys, ["mesh", "build", str(prism), "--out", str(out)],
                   f"{out}: unsupported output format '.stl'")
    assert not out.exists()


def test_target_tets_must_be_positive(capsys, prism):
    assert main(["mesh", "info", str(prism), "--target-tets", "0"]) == 2
    assert "--target-tets: 0 is not positive" in capsys.readouterr().err


def test_a_unitless_mesh_is_refused_with_its_size_and_the_scale_to_use(capsys, prism_cm, tmp_path):
    assert_refused(capsys, ["mesh", "info", str(prism_cm)],
                   f"{prism_cm}: implausible size for an organ: 6 x 6 x 4 m across, 72 m^3")
    out = tmp_path / "never.msh"
    assert main(["mesh", "build", str(prism_cm), "--out", str(out)]) == 2
    assert "--scale 0.01 " in capsys.readouterr().err and not out.exists()


def test_info_scale_turns_the_file_units_into_metres(capsys, prism_cm):
    info = run_json(capsys, prism_cm, "--scale", "0.01")
    assert info["size_m"] == pytest.approx([SIDE, SIDE, HEIGHT])
    assert info["volume_m3"] == pytest.approx(SIDE * SIDE / 2 * HEIGHT)
    assert main(["mesh", "info", str(prism_cm), "--scale", "0.01"]) == 0
    assert "size            0.06 x 0.06 x 0.04 m" in capsys.readouterr().out


def test_build_scale_writes_the_mesh_in_metres(capsys, prism, prism_cm, tmp_path):
    out = tmp_path / "metres.vtu"
    assert main(["mesh", "build", str(prism_cm), "--scale", "0.01", "--out", str(out)]) == 0
    capsys.readouterr()
    written = load_mesh(out)  # no scale: the file is in metres now
    np.testing.assert_allclose(written.points, load_mesh(prism).points, atol=1e-12)
    assert written.volume == pytest.approx(SIDE * SIDE / 2 * HEIGHT)


@pytest.mark.parametrize("value, reason", [("0", "--scale: 0.0 is not a finite number > 0"),
                                           ("-1", "--scale: -1.0 is not a finite number > 0"),
                                           ("cm", "--scale: 'cm' is not a number")])
def test_scale_must_be_a_positive_number(capsys, prism_cm, value, reason):
    assert main(["mesh", "info", str(prism_cm), f"--scale={value}"]) == 2
    assert reason in capsys.readouterr().err


def test_scale_without_a_file_is_refused(capsys):
    assert_refused(capsys, ["mesh", "info", "--scale", "0.01"], "--scale applies to a mesh file")


def test_module_entry_point_in_a_subprocess(prism, garbage):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}

    def run(*args):
        return subprocess.run([sys.executable, "-m", "liver_sim.cli.main", "mesh", "info", *map(str, args)],
                              capture_output=True, text=True, env=env, cwd=REPO, timeout=120)

    good = run(prism, "--json")
    assert good.returncode == 0, good.stderr
    assert json.loads(good.stdout)["tetrahedra"] == 3
    bad = run(garbage)
    assert bad.returncode == 2
    assert bad.stderr.startswith(f"liver-sim: error: {garbage}: unreadable Gmsh file")
    assert "Traceback" not in bad.stderr


def test_warm_compiles_the_kernels_the_physics_node_steps_with(capsys):
    """`liver-sim warm` (run by `make venv`) builds the default model with each integrator and warms it up:
    afterwards the kernels of an implicit and an explicit frame are compiled in this process, so a node started
    next finds them in numba's cache."""
    from liver_sim.physics.solver import explicit_kernels, implicit_kernels, pcg

    assert main(["warm"]) == 0
    assert "compiled and cached" in capsys.readouterr().out
    assert implicit_kernels.implicit_step.signatures and pcg.pcg_resumable.signatures  # the step, the compliance
    assert explicit_kernels.run_frame.signatures
