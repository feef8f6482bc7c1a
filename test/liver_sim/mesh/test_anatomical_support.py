"""Support regions from anatomy (anatomical_support.py) on boxes of known nodes: the bare area over the superior
posterior skin, spheres over a contact, the skin nodes held, the user's rows, and the parameter file's round trip
and refusals."""
import math

import numpy as np
import pytest
import yaml

from liver_sim.mesh.anatomical_support import (
    MIN_HELD_NODES,
    SUPPORT_STIFFNESS_N_PER_M3,
    bare_area_region,
    contact_regions,
    held_skin_nodes,
    read_support,
    support_path,
    user_regions,
    write_support,
)
from liver_sim.mesh.tetmesh import MeshError

from meshes import box_mesh


def test_the_bare_area_is_over_the_superior_posterior_edge_and_15_percent_of_the_largest_side():
    mesh = box_mesh(10, 4, 4, 0.01)  # 10 × 4 × 4 cm: its superior posterior edge runs along x at y = z = 4 cm
    x, y, z, radius, stiffness = bare_area_region(mesh)
    assert (y, z) == pytest.approx((0.04, 0.04), abs=1e-12) and 0.0 <= x <= 0.1
    assert np.isclose(mesh.points[mesh.skin_nodes], (x, y, z), atol=1e-9).all(axis=1).any()  # centred on a node
    assert radius == pytest.approx(0.15 * 0.1)  # 1.5 cm holds 7 nodes or more: itself, 3-4 at 1 cm, 3-4 at 1.41 cm
    assert stiffness == SUPPORT_STIFFNESS_N_PER_M3
    assert held_skin_nodes(mesh, [(x, y, z, radius)]) >= MIN_HELD_NODES


def test_on_a_coarse_mesh_the_bare_area_grows_to_hold_enough_skin_nodes():
    mesh = box_mesh(4, 1, 1, 0.05)  # 20 × 5 × 5 cm: 15 % of 20 cm (3 cm) holds no node beside the centre
    x, y, z, radius, _ = bare_area_region(mesh)
    assert (y, z) == pytest.approx((0.05, 0.05), abs=1e-12)
    # around a node of that edge: 3 or 4 nodes at 5 cm, as many at 7.07 cm, the next at 8.66 cm: six held (the
    # centre among them) need 7.07 cm, and less than 8.66 cm
    assert 0.05 * math.sqrt(2) <= radius < 0.05 * math.sqrt(3)
    assert held_skin_nodes(mesh, [(x, y, z, radius)]) >= MIN_HELD_NODES
    assert held_skin_nodes(mesh, [(x, y, z, 0.03)]) < MIN_HELD_NODES


def test_held_skin_nodes_counts_skin_nodes_in_any_region_once():
    mesh = box_mesh(2, 2, 2, 0.05)  # 27 nodes: all but the centre are on the skin
    assert held_skin_nodes(mesh, [(0.0, 0.0, 0.0, 0.051)]) == 4  # a corner and its three neighbours
    assert held_skin_nodes(mesh, [(0.05, 0.0, 0.0, 0.051)]) == 5  # an edge's middle, its two ends, two on faces
    assert held_skin_nodes(mesh, [(0.0, 0.0, 0.0, 0.051, 1e6), (0.05, 0.0, 0.0, 0.051, 1e6)]) == 7  # 2 shared
    assert held_skin_nodes(mesh, [(0.05, 0.05, 0.05, 0.049)]) == 0  # the centre node is inside, not skin


def test_contact_spheres_hold_their_points_one_per_occupied_cell():
    near = np.array([[0.001, 0.002, 0.003], [0.005, 0.004, 0.006], [0.009, 0.010, 0.002]])  # one 12 mm cell
    far = np.array([[0.101, 0.102, 0.103], [0.104, 0.105, 0.101]])  # another
    regions = contact_regions(np.vstack([near, far]))
    assert len(regions) == 2
    for points, (x, y, z, radius, stiffness) in zip((near, far), sorted(regions)):
        assert (x, y, z) == pytest.approx(tuple(points.mean(axis=0)), abs=1e-6)
        assert np.linalg.norm(points - (x, y, z), axis=1).max() < radius
        assert stiffness == SUPPORT_STIFFNESS_N_PER_M3


def test_user_regions_are_rows_of_five_positive_numbers():
    assert user_regions(["0", "0.01", "-0.02", "0.03", "1e6", 1, 2, 3, 0.5, 2e6]) == [
        (0.0, 0.01, -0.02, 0.03, 1e6), (1.0, 2.0, 3.0, 0.5, 2e6)]


@pytest.mark.parametrize("values, message", [
    ([], "five finite numbers per sphere .* got 0 numbers"),
    ([0, 0, 0, 0.01], "got 4 numbers"),
    ([0, 0, 0, 0.01, 1e6, 1], "got 6 numbers"),
    ([0, 0, math.nan, 0.01, 1e6], "five finite numbers"),
    ([0, 0, 0, 0.0, 1e6], "every radius and stiffness must be > 0"),
    ([0, 0, 0, 0.01, -1.0], "every radius and stiffness must be > 0"),
])
def test_user_regions_refusals_name_the_option(values, message):
    with pytest.raises(ValueError, match=rf"^--support-regions.*{message}"):
        user_regions(values)


def test_the_support_file_sits_beside_the_mesh():
    assert support_path("/cases/liver.msh").as_posix() == "/cases/liver.support.yaml"
    assert support_path("patient.vtu").as_posix() == "patient.support.yaml"


def test_the_support_file_is_the_physics_nodes_parameters_and_reads_back(tmp_path):
    regions = [(0.01, 0.02, 0.03, 0.04, 1e6), (-0.01, 0.0, 0.05, 0.02, 2e6)]
    path = write_support(tmp_path / "liver.support.yaml", regions, "support: a test")
    assert path.read_text().startswith("# support: a test\n")
    assert yaml.safe_load(path.read_text()) == {"liver_physics": {"ros__parameters": {
        "support": "organ", "support_regions": [0.01, 0.02, 0.03, 0.04, 1e6, -0.01, 0.0, 0.05, 0.02, 2e6]}}}
    assert read_support(path) == {"support": "organ",
                                  "support_regions": [0.01, 0.02, 0.03, 0.04, 1e6, -0.01, 0.0, 0.05, 0.02, 2e6]}


@pytest.mark.parametrize("text, defect", [
    (None, "not a support file (FileNotFoundError"),
    ("liver_physics: [unclosed\n", "not a support file (ParserError"),
    ("other_node:\n  ros__parameters:\n    support_regions: [0, 0, 0, 0.01, 1]\n", "not a support file (KeyError"),
    ("liver_physics:\n  ros__parameters:\n    support_regions: [0, 0, 0, 0.01]\n", "five numbers per sphere"),
    ("liver_physics:\n  ros__parameters:\n    support_regions: []\n", "five numbers per sphere"),
    ("liver_physics:\n  ros__parameters:\n    support_regions: [0, 0, 0, 0.01, 1]\n    mass_kg: 2\n",
     "support and support_regions (five numbers per sphere) only"),
])
def test_anything_else_in_a_support_file_is_refused_naming_it(tmp_path, text, defect):
    path = tmp_path / "liver.support.yaml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(MeshError) as caught:
        read_support(path)
    assert str(caught.value).startswith(f"{path}: ") and defect in caught.value.defect
