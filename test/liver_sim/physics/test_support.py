"""`liver-sim validate` on the default liver, held by its support (B1–B4, R1 with the liver's materials, the local
model's continuity): the whole model (the support's parts: tissue/test_organ_support.py)."""
import json

import numpy as np
import pytest

from liver_sim.cli.main import main
from liver_sim.studies.validate import figures_json


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
