"""The MuJoCo peer (liver_sim.studies.peers): the flex it builds from our mesh, its stability check, and the clear
error when the optional extra is not installed."""
import sys

import numpy as np
import pytest

from liver_sim.cli import main as cli
from liver_sim.studies import peers

from meshes import box_mesh

E_PA, NU, RHO, DAMPING_S = 5000.0, 0.25, 1060.0, 0.1


@pytest.fixture
def box():
    """A 4 × 3 × 2 cm box of 1 cm cubes, its bottom face fixed."""
    mesh = box_mesh(4, 3, 2, 0.01)
    return mesh, np.flatnonzero(mesh.points[:, 2] == 0.0)


@pytest.fixture
def no_mujoco(monkeypatch):
    """`import mujoco` fails as if the extra were not installed."""
    monkeypatch.setitem(sys.modules, "mujoco", None)


def test_without_mujoco_the_peer_names_the_extra_to_install(no_mujoco, box):
    mesh, fixed = box
    with pytest.raises(ImportError, match=r"pip install \.\[peers\]"):
        peers.time_mujoco_flex(mesh, E_PA, NU, RHO, fixed)


def test_without_mujoco_bench_peers_is_refused_before_benchmarking(no_mujoco, capsys):
    assert cli.main(["bench", "physics", "--peers", "--sizes"]) == cli.EXIT_REFUSED
    assert "pip install .[peers]" in capsys.readouterr().err


def test_flex_has_every_node_and_the_lumped_mass_of_the_free_ones(box):
    pytest.importorskip("mujoco")
    mesh, fixed = box
    _, model = peers.build_flex(mesh, E_PA, NU, RHO, fixed, DAMPING_S)
    free = np.setdiff1d(np.arange(len(mesh.points)), fixed)
    masses = mesh.lumped_masses(RHO)
    assert model.nflexvert == len(mesh.points) and model.nflexelem == len(mesh.tets)
    assert model.nv == 3 * len(free)
    body = model.flex_vertbodyid
    assert np.all(body[fixed] == 0)  # pinned to the world
    np.testing.assert_allclose(model.body_mass[body[free]], masses[free], rtol=1e-9)
    assert len(np.unique(body[free])) == len(free)  # one body per free node
    assert model.flex_damping[0] == pytest.approx(DAMPING_S)


def test_one_second_of_the_press_stays_finite_pinned_nodes_stay_put_and_the_box_pushes_back(box):
    pytest.importorskip("mujoco")
    mesh, fixed = box
    result = peers.time_mujoco_flex(mesh, E_PA, NU, RHO, fixed, frames=150, damping_s=DAMPING_S)
    assert result["stable"] and result["frames"] == 150 and result["under_converged_steps"] == 0
    assert result["fixed_nodes_max_displacement_m"] < 1e-12
    assert result["max_displacement_m"] > 0.25 * peers.PRESS_DEPTH_M  # the top was pressed in
    force = np.asarray(result["tool_force_n"])
    assert np.isfinite(force).all() and force[2] > 0.0  # the box pushes the sphere up
    assert result["free_mass_kg"] == pytest.approx(np.delete(mesh.lumped_masses(RHO), fixed).sum(), rel=1e-9)
    assert result["steps_per_frame"] == 1 and result["mujoco_version"]
    assert np.isfinite([result["ms_per_frame_mean"], result["ms_per_frame_median"], result["ms_per_frame_p90"]]).all()


def test_an_explicit_step_of_a_whole_frame_is_reported_unstable(box):
    pytest.importorskip("mujoco")
    mesh, fixed = box
    result = peers.time_mujoco_flex(mesh, E_PA, NU, RHO, fixed, frames=150,
                                    settings=peers.FlexSettings(integrator="Euler"))
    assert not result["stable"] and result["frames"] < 150


def test_bench_hook_reports_the_peer_and_the_ratio(box):
    pytest.importorskip("mujoco")
    from liver_sim.bench.physics import peer_figures

    mesh, _ = box
    figures = peer_figures(mesh, liver_sim_ms_per_frame=2.0)
    assert figures["peer"]["stable"]
    assert figures["peer_ms_per_frame"] == pytest.approx(figures["peer"]["ms_per_frame_mean"], abs=1e-3)
    assert figures["peer_ratio"] == pytest.approx(figures["peer"]["ms_per_frame_mean"] / 2.0, abs=1e-3)


def test_bad_material_is_refused_by_name(box):
    mesh, fixed = box
    with pytest.raises(ValueError, match="poisson_ratio"):
        peers.flex_mjcf(mesh, E_PA, 0.5, fixed)
    with pytest.raises(ValueError, match="fixed_nodes"):
        peers.flex_mjcf(mesh, E_PA, NU, [len(mesh.points)])
