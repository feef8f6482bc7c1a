"""The physics benchmark's report, the frame time of two contacts, and the headless demo's outputs (behaviour, not
speed)."""
import json

import pytest

from liver_sim.bench.physics import contact_frame_times, run_physics_bench
from liver_sim.bench.topology import TOPOLOGY_TARGETS, run_topology_bench
from liver_sim.mesh.tetmesh import MeshError
from liver_sim.studies.demo_liver import DemoMesh
from liver_sim.studies.demo_offline import PLOTTED_FIGURES, run_offline_demo

from meshes import write_sphere_surface

PNG = b"\x89PNG\r\n\x1a\n"


def test_the_frame_time_of_two_contacts_is_measured_with_both_tools_pressing():
    from liver_sim.bench.loop import HAND_SPOTS_XY
    from liver_sim.mesh.landmarks import upper_skin_point
    from liver_sim.mesh.liver_shape import default_liver

    liver = default_liver()
    figures = contact_frame_times([upper_skin_point(liver, xy) for xy in HAND_SPOTS_XY.values()], frames=30,
                                  approach_frames=20)
    assert [figures[label]["tools_in_contact"] for label in ("one_contact", "two_contacts")] == [1, 2]
    for row in figures.values():
        assert row["frames"] == 10 and 0.0 < row["median_ms"] <= row["p99_ms"]


def test_physics_bench_reports_the_default_liver_first_and_agrees_with_numpy():
    report = run_physics_bench(sizes=(3000,), min_seconds=0.02)
    assert {"cpu", "cores", "numba"} <= set(report["machine"])
    first, second = report["results"]
    assert first["mesh"] == "default liver" and 1100 <= first["tetrahedra"] <= 1200
    assert 2700 <= second["tetrahedra"] <= 3300
    for result in report["results"]:
        assert {"mesh", "tetrahedra", "springs", "us_per_step_1thread", "us_per_step_all_threads",
                "numpy_us_per_step", "stable_dt_s", "realtime_factor_150hz"} <= set(result)
        assert result["max_abs_diff_vs_numpy_m"] < 1e-9
        assert result["us_per_step_1thread"] > 0 and result["realtime_factor_150hz"] > 0
        rows = {(row["integrator"], row["tissue_law"]): row for row in result["integrators"]}
        assert set(rows) == {("implicit_euler", "springs"), ("implicit_euler", "fem"),
                             ("implicit_euler", "neo_hookean"), ("symplectic_euler", "springs")}
        assert rows[("implicit_euler", "fem")]["steps_per_frame"] == 1
        assert rows[("implicit_euler", "neo_hookean")]["steps_per_frame"] == 1
        for row in rows.values():  # the worst frames beside the mean
            assert row["ms_per_frame_p99_1thread"] > 0.0 and row["ms_per_frame_p99_all_threads"] > 0.0
        rows = {integrator: rows[(integrator, "springs")] for integrator in ("implicit_euler", "symplectic_euler")}
        assert rows["implicit_euler"]["steps_per_frame"] == 1
        assert rows["symplectic_euler"]["steps_per_frame"] == result["substeps_per_frame"] > 1
        assert rows["symplectic_euler"]["max_position_error_vs_reference_m"] == 0.0  # it is the reference
        assert 0.0 < rows["implicit_euler"]["max_position_error_vs_reference_m"] < 1e-3
        for row in rows.values():
            assert row["ms_per_frame_1thread"] > 0 and row["ms_per_frame_all_threads"] > 0
            assert row["realtime_factor_150hz"] > 0 and row["realtime_factor_all_threads"] > 0
        assert rows["implicit_euler"]["cg_iterations_per_step"] > 0
        assert rows["implicit_euler"]["solver"].startswith("pcg ")
        assert 0 < result["model_rss_mb"] < result["peak_rss_mb"]
        assert result["peak_rss_mb_per_100k_tets"] == pytest.approx(result["peak_rss_mb"] / result["tetrahedra"] * 1e5,
                                                                    rel=0.01)
    assert "default_implicit_ms_per_frame_1thread_max" in report["met"]
    assert rows["implicit_euler"]["solver"].startswith("pcg two-level")  # ~3000 tets: over TWO_LEVEL_MIN_NODES
    json.dumps(report)


def test_topology_bench_tears_and_cuts_each_mesh_and_reports_its_target():
    report = json.loads(json.dumps(run_topology_bench(sizes=(2000,), repeats=1)))
    assert report["machine"]["cores"] and set(report["met"]) == set(TOPOLOGY_TARGETS)
    default, larger = report["results"]
    assert default["mesh"] == "default liver" and larger["tetrahedra"] > default["tetrahedra"]
    for result in (default, larger):
        assert result["tear_faces_opened"] > 0
        assert 0.0 < result["tear_detection_per_frame_s"] < result["tear_s"]
        assert result["cut_s"] > 0.0 and result["cut_new_nodes"] > 0


def test_offline_demo_writes_summary_and_pictures(tmp_path):
    summary = run_offline_demo(tmp_path, duration_s=3.0, progress=lambda line: None)
    for name in PLOTTED_FIGURES:
        assert (tmp_path / name).read_bytes()[:8] == PNG
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["peak_force_n"] == pytest.approx(summary["peak_force_n"])
    assert summary["peak_force_n"] > 0.2 and not summary["divergences"]
    assert summary["simulated_s"] == pytest.approx(3.0, abs=0.01)
    assert "Press-and-release" in (tmp_path / "summary.md").read_text()


def test_offline_demo_refuses_a_duration_shorter_than_the_script(tmp_path):
    with pytest.raises(ValueError, match="--duration"):
        run_offline_demo(tmp_path, duration_s=1.0, progress=lambda line: None)


def test_offline_demo_presses_a_users_mesh_in_its_units_where_it_lies(tmp_path):
    path = write_sphere_surface(tmp_path / "organ_cm.stl", 6.0, centre=(30.0, -20.0, 10.0), subdivisions=2)
    with pytest.raises(MeshError, match="--scale 0.01 "):
        run_offline_demo(tmp_path / "unitless", progress=lambda line: None, liver=DemoMesh(path))
    summary = run_offline_demo(tmp_path / "out", duration_s=2.5, progress=lambda line: None,
                               liver=DemoMesh(path, 0.01))
    assert summary["mesh"]["source"] == str(path) and summary["mesh"]["scale"] == 0.01
    assert summary["mesh"]["size_m"] == pytest.approx([0.12] * 3, rel=0.08)
    assert summary["peak_force_n"] > 0.2 and not summary["divergences"]  # the tool met the sphere's top
    assert summary["peak_displacement_m"] > 0.005
    for name in PLOTTED_FIGURES:
        assert (tmp_path / "out" / name).read_bytes()[:8] == PNG
    assert "organ_cm.stl" in (tmp_path / "out" / "summary.md").read_text()
