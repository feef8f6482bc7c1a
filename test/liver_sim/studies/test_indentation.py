"""The sphere pressed into a bonded block (`liver-sim validate indentation`): the expected force, the surface
contact that does not sink, and the held tool settling."""
import math

import pytest

from liver_sim.cli.main import main
from liver_sim.physics.settings import ModelParams
from liver_sim.studies.indentation import (
    PENETRATION_MAX_M,
    block_mesh,
    bonded_layer_factor,
    default_variant,
    hertz_force_n,
    indent,
    reference_forces_n,
    variants,
)


def test_hertz_force_of_the_default_sphere_at_5_mm():
    # 4/3 · 2 kPa/(1 − 0.45²) · √0.015 m · (5 mm)^1.5, worked out by hand
    assert hertz_force_n(2000.0, 0.45, 0.015, 0.005) == pytest.approx(0.14479, rel=1e-4)


def test_bonded_layer_factor_is_dimitriadis_series_for_an_incompressible_layer():
    # ν = 0.5: 1 + 1.133χ + 1.283χ² + 0.769χ³ + 0.0975χ⁴ (Dimitriadis et al. 2002, bonded sample)
    radius, thickness = 0.015, 0.06
    for depth in (0.001, 0.005, 0.02):
        chi = math.sqrt(radius * depth) / thickness
        series = 1 + 1.133 * chi + 1.283 * chi ** 2 + 0.769 * chi ** 3 + 0.0975 * chi ** 4
        assert bonded_layer_factor(0.5, radius, depth, thickness) == pytest.approx(series, rel=2e-3)
    assert bonded_layer_factor(0.45, radius, 1e-12, thickness) == pytest.approx(1.0, abs=1e-5)
    assert 1.0 < bonded_layer_factor(0.45, radius, 0.001, thickness) < bonded_layer_factor(0.45, radius, 0.005,
                                                                                             thickness)


def test_the_surface_contact_holds_nodes_and_faces_where_the_probe_contact_sinks_and_both_settle():
    mesh = block_mesh(3000)
    runs = {name: indent(mesh, params, depths_m=(0.002, 0.004)) for name, params in variants(ModelParams()).items()}
    surface = runs["springs default, surface contact"]["rows"]
    probe = runs["springs default, probe contact"]["rows"]
    assert all(row["node_penetration_m"] <= PENETRATION_MAX_M for row in surface)
    assert all(row["face_dip_over_sagitta_m"] <= PENETRATION_MAX_M for row in surface)
    assert all(row["sink_m"] > 2.0 * s["node_penetration_m"] for row, s in zip(probe, surface))
    for run in runs.values():  # static equilibrium found at every depth (the hold's figure: validate's)
        rows = run["rows"]
        assert rows[1]["force_n"] > rows[0]["force_n"] > 0.0
        assert all(row["settled"] for row in rows)
    linear = runs["springs linear, surface contact"]["rows"]
    assert linear[1]["force_n"] < surface[1]["force_n"]  # the cubic term stiffens


def test_the_surface_contact_needs_the_implicit_integrator_and_a_known_model():
    with pytest.raises(ValueError, match="contact_model"):
        ModelParams(contact_model="surface", integrator="symplectic_euler").validate()
    with pytest.raises(ValueError, match="contact_model"):
        ModelParams(contact_model="volume").validate()


def test_the_default_variant_is_the_products_own_tissue_and_contact():
    for params in (ModelParams(), ModelParams(contact_model="surface")):
        name = default_variant(params)
        assert variants(params)[name] == params and params.contact_model in name


def test_a_probe_tip_is_pressed_and_referenced_at_its_own_radius():
    params = variants(ModelParams())["springs default, surface contact"]
    # on 3 000 tets no node lies under a 5 mm sphere 1 mm deep: the reference (nodes only) feels nothing
    assert reference_forces_n(block_mesh(3000), params, (0.001,), 0.005) == [0.0]
    mesh = block_mesh(8000)
    tip, ball = (reference_forces_n(mesh, params, (0.001,), radius) for radius in (0.005, 0.015))
    assert 0.0 < tip[0] < ball[0]  # a smaller sphere meets less tissue at the same depth
    run = indent(mesh, params, depths_m=(0.001,), reference_n=tip, radius_m=0.005)
    row = run["rows"][0]
    assert run["sphere_radius_m"] == 0.005 and row["reference_n"] == tip[0]
    tissue = params.tissue
    assert row["hertz_n"] == pytest.approx(hertz_force_n(tissue.parenchyma_young_modulus_kpa * 1e3,
                                                         tissue.parenchyma_poisson_ratio, 0.005, 0.001))
    assert row["force_n"] > 0.0 and row["settled"]


def test_the_sphere_options_are_for_the_indentation_only(capsys):
    for option in (["--radius", "0.005"], ["--depths", "0.001"]):
        with pytest.raises(SystemExit, match=f"{option[0]} is for validate indentation"):
            main(["validate", *option])
