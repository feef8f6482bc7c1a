"""The organ's support (physics.tissue.organ_support) and `liver-sim validate` on the default liver (B1–B4, R1 with the
liver's materials, the local model's continuity)."""
import json

import numpy as np
import pytest

from liver_sim.cli.main import main
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.model import LiverModel
from liver_sim.physics.parameters import model_params
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import implicit_kernels, reference
from liver_sim.physics.solver.records import Operator
from liver_sim.physics.structure import default_fixed_nodes
from liver_sim.physics.tissue.organ_support import SupportArrays, build_support, support_forces
from liver_sim.sessions.parameters import node_parameters
from liver_sim.studies.validate import figures_json


def random_support(count=6, nodes=20, seed=0):
    rng = np.random.default_rng(seed)
    x, v = rng.normal(size=(nodes, 3)), rng.normal(size=(nodes, 3))
    support = SupportArrays(rng.choice(nodes, count, replace=False).astype(np.int64), rng.normal(size=(count, 3)),
                            rng.uniform(10, 100, count), rng.uniform(0.1, 1, count))
    return x, v, support


def test_support_force_and_jacobian_in_both_integrators():
    x, v, support = random_support()
    expected = reference.support_forces(x, v, support)
    f = np.zeros_like(x)
    support_forces(x, v, *support, f)
    np.testing.assert_allclose(f, expected, rtol=1e-12)
    inv_mass = np.ones(len(x))
    inv_mass[support.nodes[0]] = 0.0  # a held node: no force, no matrix entry

    def implicit_terms(xs, vs, y, h=0.01):
        f, ky = np.zeros_like(xs), np.zeros_like(xs)
        none = np.zeros(0, np.uint32)
        op = Operator.allocate(none, none, len(xs))
        implicit_kernels.support_terms(xs, vs, y, inv_mass, h, support, f, ky, op, True)
        return f, ky, op.shift, op.diagonal

    direction = np.random.default_rng(1).normal(size=x.shape)
    f, ky, shift, diagonal = implicit_terms(x, v, direction)
    free = inv_mass > 0.0
    np.testing.assert_allclose(f[free], expected[free], rtol=1e-12)
    eps = 1e-6
    dfdx = (implicit_terms(x + eps * direction, v, direction)[0] - implicit_terms(x - eps * direction, v,
                                                                                  direction)[0]) / (2 * eps)
    np.testing.assert_allclose(ky, dfdx, atol=1e-6)
    k, c = np.zeros(len(x)), np.zeros(len(x))
    k[support.nodes], c[support.nodes] = support.stiffness_n_per_m, support.damping_ns_per_m
    np.testing.assert_allclose(shift, np.where(free, 1.0 + 0.01 * c + 1e-4 * k, 1.0))
    assert shift[support.nodes[0]] == 1.0 and not f[support.nodes[0]].any()


def test_the_organ_support_holds_the_default_liver_and_the_paper_scene_stays_selectable():
    liver = default_liver()
    organ, paper = LiverModel(liver), LiverModel(liver, ModelParams(support="paper"))
    support = organ.structure.support
    assert organ.structure.fixed_nodes.size == 0 and len(support.nodes) >= 20
    assert np.isin(support.nodes, liver.skin_nodes).all() and (support.stiffness_n_per_m > 0).all()
    # the bare area and the vena cava are posterior: most of the tie stiffness holds the posterior face
    posterior = liver.points[support.nodes, 1] > 0.02
    assert support.stiffness_n_per_m[posterior].sum() > 0.8 * support.stiffness_n_per_m.sum()
    assert np.array_equal(paper.structure.fixed_nodes, default_fixed_nodes(liver))
    assert len(paper.structure.support.nodes) == 0
    # regions that hold no skin node of a mesh: the paper's scene
    far = ModelParams(support_regions=((1.0, 1.0, 1.0, 0.01, 1e6),))
    assert len(build_support(liver, liver.skin, far).nodes) == 0
    assert np.array_equal(LiverModel(liver, far).structure.fixed_nodes, default_fixed_nodes(liver))


def test_support_parameters_are_checked_and_the_config_gives_the_defaults():
    assert model_params(node_parameters()["liver_physics"]) == ModelParams()
    values = node_parameters()["liver_physics"].replace(support_regions=[0.0, 0.0, 0.0, 0.01])
    with pytest.raises(ValueError, match="support_regions"):
        model_params(values)
    with pytest.raises(ValueError, match="support_regions"):
        ModelParams(support_regions=((0.0, 0.0, 0.0, -0.01, 1.0),)).validate()
    with pytest.raises(ValueError, match="support"):
        ModelParams(support="pinned").validate()


@pytest.fixture(scope="module")
def validated(tmp_path_factory):
    out = tmp_path_factory.mktemp("validate")
    status = main(["validate", "--out", str(out)])
    return status, json.loads((out / "validate.json").read_text()), out


def by_name(report, check):
    return {f["name"]: f for f in report["figures"] if f["check"] == check}


def test_validate_reports_every_figure_and_a_plot_per_behaviour(validated):
    status, report, out = validated
    checks = {f["check"] for f in report["figures"]}
    assert checks == {"B1", "B2", "B3", "B4", "continuity", "R1"}
    for figure in report["figures"]:
        assert {"name", "value", "threshold", "kind", "unit", "met"} <= set(figure)
        assert np.isfinite(figure["value"])
        assert figure["met"] == (figure["value"] <= figure["threshold"] if figure["kind"] == "max"
                                 else figure["value"] >= figure["threshold"])
    assert report["all_met"] == all(f["met"] for f in report["figures"]) == (status == 0)
    assert len(by_name(report, "R1")) == 4  # parenchyma, and parenchyma with the capsule
    for name in ("b1.png", "b2_b3.png", "b4_continuity.png", "traction_materials.png"):
        assert (out / name).read_bytes().startswith(b"\x89PNG")
    assert figures_json([])["all_met"]


def test_a_10_mm_press_deforms_the_liver_under_the_tool_without_turning_it(validated):
    b1 = by_name(validated[1], "B1")
    assert b1["distance of the largest displacement to the tool"]["value"] < 0.03
    assert b1["rigid rotation of the organ"]["value"] < 2.0
    assert all(f["met"] for f in b1.values())


def test_the_supported_liver_returns_to_rest_slowly_after_a_strong_press(validated):
    assert all(f["met"] for f in by_name(validated[1], "B2").values())
    assert all(f["met"] for f in by_name(validated[1], "B3").values())
