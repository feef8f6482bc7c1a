"""R1 of docs/paper.md (Figs. 4–5): the cylinder's global force–elongation curve has the connector law's shape."""
import csv

import numpy as np
import pytest

from liver_sim.traction import run_traction, write_traction


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
