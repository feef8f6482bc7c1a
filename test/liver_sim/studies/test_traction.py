"""R1 of docs/paper.md (Figs. 4–5): the cylinder's global force–elongation curve has the connector law's shape,
with Fig. 2's law (the paper's set-up) and with the liver's materials (clamped)."""
import csv

import numpy as np
import pytest

from liver_sim.physics.settings import TissueProperties
from liver_sim.studies.traction import (
    CLAMP_LENGTH_M,
    CLAMPED_SPACING_M,
    TARGET_STRAINS,
    cylinder_mesh,
    run_traction,
    section_stiffness_n,
    write_traction,
)
from liver_sim.studies.validate import TRACTION_SHAPE_TOLERANCE, TRACTION_STIFFNESS_TOLERANCE


@pytest.fixture(scope="module")
def traction():
    return run_traction()


def test_global_curve_is_linear_at_small_strain(traction):
    small = traction.elongation < 0.025
    assert small.sum() >= 3
    secant = traction.force_n[small] / traction.elongation[small]
    assert secant.max() / secant.min() < 1.1


def test_global_curve_stiffens_sharply_beyond_ten_percent(traction):
    assert np.all(np.diff(traction.elongation) > 0)
    tangent = np.diff(traction.force_n) / np.diff(traction.elongation)
    small_strain = traction.force_n[0] / traction.elongation[0]
    assert tangent[-1] > 10 * small_strain
    assert traction.elongation.max() > 0.2


def test_global_curve_follows_the_scaled_connector_law(traction):
    # the same shape: within 25 % of the law at every level (the cylinder also narrows as it stretches)
    law = traction.law_force_n(traction.elongation)
    np.testing.assert_allclose(traction.force_n, law, rtol=0.25)
    np.testing.assert_allclose(traction.force_n[:4], law[:4], rtol=0.05)


def test_csv_and_png_are_written(traction, tmp_path):
    csv_path, png_path = write_traction(traction, tmp_path)
    with csv_path.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(traction.force_n)
    assert {"force_N", "elongation"} <= set(rows[0])
    assert float(rows[-1]["force_N"]) == pytest.approx(traction.force_n[-1])
    assert png_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def clamped_cylinder():
    return cylinder_mesh(CLAMPED_SPACING_M)


@pytest.mark.parametrize("capsule", [False, True], ids=["parenchyma", "capsule+parenchyma"])
def test_clamped_cylinder_of_the_liver_materials_meets_r1(clamped_cylinder, capsule):
    # validate's R1: small-strain stiffness within 30 % of the section's E·πR² (+ Y·2πR), shape within 25 %
    tissue = TissueProperties() if capsule else TissueProperties(capsule_stiffness_n_per_m=0.0)
    result = run_traction(mesh=clamped_cylinder, tissue=tissue, clamp_length_m=CLAMP_LENGTH_M)
    assert result.small_strain_stiffness_n / section_stiffness_n(tissue) == pytest.approx(
        1.0, abs=TRACTION_STIFFNESS_TOLERANCE)
    assert result.shape_deviation() <= TRACTION_SHAPE_TOLERANCE
    # the extensometer reads the gauge's middle: near, not at, the strain the clamps impose
    assert np.all(np.diff(result.elongation) > 0)
    np.testing.assert_allclose(result.elongation, TARGET_STRAINS, rtol=0.1)
    assert np.abs(result.elongation / np.array(TARGET_STRAINS) - 1.0).max() > 1e-3


def test_paper_set_up_misses_the_capsule(clamped_cylinder):
    # forces on the bottom face load the parenchyma only: the capsule is barely pulled (docs/paper.md, R1)
    tissue = TissueProperties()
    result = run_traction(mesh=clamped_cylinder, tissue=tissue)
    assert result.small_strain_stiffness_n / section_stiffness_n(tissue) < 1.0 - TRACTION_STIFFNESS_TOLERANCE
