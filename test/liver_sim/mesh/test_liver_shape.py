"""The embedded default liver (paper P1 of docs/paper.md: 1151 tets, 370 skin triangles): size, quality,
reproducibility."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from liver_sim.mesh.liver_shape import DEFAULT_TARGET_TETS, build_liver, default_liver, liver_signed_distance

REPO = Path(__file__).resolve().parents[3]
# Nominal liver size in frame `liver` (x left-right, y antero-posterior, z cranio-caudal), metres.
NOMINAL_SIZE = np.array([0.25, 0.15, 0.13])


@pytest.fixture(scope="module")
def liver():
    return default_liver()


def test_tet_and_skin_counts_match_the_paper_scale(liver):
    assert 1100 <= len(liver.tets) <= 1200
    assert 200 <= len(liver.skin) <= 700
    assert f"{len(liver.tets)} tets" in liver.source


def test_volume_and_bounding_box_are_those_of_a_human_liver(liver):
    assert 1.3e-3 <= liver.volume <= 1.7e-3
    size = liver.bounds[1] - liver.bounds[0]
    assert np.all(np.abs(size / NOMINAL_SIZE - 1.0) <= 0.2), size


def test_mesh_is_closed_and_well_shaped(liver):
    assert liver.watertight
    assert liver.dihedral_angles_deg.min() >= 10.0
    assert liver.dihedral_angles_deg.max() <= 170.0
    assert np.abs(liver_signed_distance(liver.points[liver.skin_nodes])).max() < 1e-9


def test_left_lobe_is_thinner_than_right_lobe(liver):
    """Cranio-caudal thickness of the outer quarter at each end: right lobe at -x, left lobe at +x."""
    points = liver.points
    lower, upper = liver.bounds
    quarter = 0.25 * (upper[0] - lower[0])
    right = np.ptp(points[points[:, 0] < lower[0] + quarter, 2])
    left = np.ptp(points[points[:, 0] > upper[0] - quarter, 2])
    assert left < 0.6 * right
    # The left lobe is still meshed through its thickness, not reduced to a skin.
    left_quarter_nodes = np.flatnonzero(points[:, 0] > upper[0] - quarter)
    assert len(np.setdiff1d(left_quarter_nodes, liver.skin_nodes)) >= 2


def test_built_once_per_process(liver):
    assert default_liver() is liver


def test_same_hash_in_a_fresh_process(liver):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    result = subprocess.run(
        [sys.executable, "-c", "from liver_sim.mesh.liver_shape import default_liver; print(default_liver().sha256)"],
        capture_output=True, text=True, env=env, cwd=REPO, timeout=120, check=True)
    assert result.stdout.strip() == liver.sha256


def test_build_liver_scales_to_benchmark_sizes():
    mesh = build_liver(10_000)
    assert abs(len(mesh.tets) - 10_000) <= 1_000
    assert mesh.watertight
    assert mesh.dihedral_angles_deg.min() >= 10.0
    assert 1.3e-3 <= mesh.volume <= 1.7e-3


def test_default_target_is_the_paper_count():
    assert abs(DEFAULT_TARGET_TETS - 1151) <= 10
