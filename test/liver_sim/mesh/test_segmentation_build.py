"""`liver-sim mesh build SEGMENTATION`: synthetic label volumes built here (NIfTI and NRRD, RAS, LPS, oblique) to
meshes that keep the label's volume (3 %) and boundary (1.5 voxels) in the patient's axes, with their support; a real
liver mask (TotalSegmentator's example, data/README.md) to a sound liver of its volume; every bad input refused in one
line with nothing written."""
import math
from pathlib import Path

import nibabel
import nrrd
import numpy as np
import pytest
from label_volumes import centred_affine, rasterise, write_nifti, write_nrrd

from liver_sim.cli.main import main
from liver_sim.mesh.anatomical_support import read_support, support_path
from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.segmentation_build import build_from_segmentation
from liver_sim.studies.demo_liver import DemoMesh

from meshes import assert_sound

SPACING_MM = np.array([0.7, 0.7, 2.5])
#: The organ, in the patient's LPS coordinates (mm): an ellipsoid wider left-right than front-back than tall,
#: with a round bump on its left, anterior, superior side, so that every axis and its sign shows in the mesh.
RADII_MM = np.array([30.0, 22.0, 18.0])
BUMP_CENTRE_MM = np.array([18.0, -10.0, 14.0])
BUMP_RADIUS_MM = 9.0
BUMP_BLEND_MM = 6.0
TARGET_TETS = 6000


def organ(lps_mm):
    return ((lps_mm / RADII_MM) ** 2).sum(axis=-1) <= 1.0


def bumped_organ(lps_mm):
    """The organ and the bump, smoothly united over BUMP_BLEND_MM (an organ has no crease sharper than that)."""
    scaled = np.linalg.norm(lps_mm / RADII_MM, axis=-1)
    ellipsoid = scaled * (scaled - 1.0) / np.maximum(np.linalg.norm(lps_mm / RADII_MM ** 2, axis=-1), 1e-9)
    bump = np.linalg.norm(lps_mm - BUMP_CENTRE_MM, axis=-1) - BUMP_RADIUS_MM
    h = np.clip(0.5 + 0.5 * (bump - ellipsoid) / BUMP_BLEND_MM, 0.0, 1.0)
    return bump + (ellipsoid - bump) * h - BUMP_BLEND_MM * h * (1.0 - h) <= 0.0


def grid_affine(shape, rotation=np.eye(3)):
    """Voxel index → LPS (mm): `rotation` × the anisotropic SPACING_MM, centred on the origin."""
    return centred_affine(shape, SPACING_MM, rotation)


def rotation(axis, degrees):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    angle = math.radians(degrees)
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


SHAPE = (100, 80, 22)


def ras_file(tmp_path):
    """The bumped organ as a RAS NIfTI whose voxel axes run left → right, posterior → anterior (RAS+ storage)."""
    affine = grid_affine(SHAPE, np.diag([-1.0, -1.0, 1.0]))
    return write_nifti(tmp_path / "organ.nii.gz", rasterise(SHAPE, affine, bumped_organ), affine), affine


def lps_file(tmp_path):
    affine = grid_affine(SHAPE)
    return write_nrrd(tmp_path / "organ.seg.nrrd", rasterise(SHAPE, affine, bumped_organ), affine), affine


def oblique_file(tmp_path):
    shape = (110, 100, 30)
    affine = grid_affine(shape, rotation((1.0, 0.4, 0.2), 25.0))
    return write_nifti(tmp_path / "oblique.nii", rasterise(shape, affine, bumped_organ), affine), affine


def build(tmp_path, path, **kwargs):
    return build_from_segmentation(path, tmp_path / "out" / "organ.msh", target_tets=TARGET_TETS, **kwargs)


def voxel_ml(affine):
    return abs(np.linalg.det(affine[:3, :3])) / 1e3


def assert_faithful(summary, reference_ml):
    """The mesh keeps the label's volume within 3 % and its boundary within 1.5 voxels, both ways."""
    assert summary["mesh_volume_ml"] == pytest.approx(reference_ml, rel=0.03)
    assert summary["max_surface_distance_voxels"] <= 1.5
    assert 0.0 < summary["max_surface_distance_mm"] <= 1.5 * SPACING_MM.max()
    assert summary["tetrahedra"] == pytest.approx(TARGET_TETS, rel=0.1)


@pytest.fixture(autouse=True)
def out_folder(tmp_path):
    (tmp_path / "out").mkdir()


@pytest.mark.parametrize("make", [ras_file, lps_file, oblique_file], ids=["RAS NIfTI", "LPS NRRD", "oblique"])
def test_an_anisotropic_organ_keeps_volume_boundary_and_patient_axes(tmp_path, make):
    path, affine = make(tmp_path)
    summary = build(tmp_path, path)
    labels = rasterise(SHAPE, affine, bumped_organ) if make is not oblique_file else None
    label_ml = summary["label_voxels"] * voxel_ml(affine)
    assert summary["label_volume_ml"] == pytest.approx(label_ml)
    if labels is not None:
        assert summary["label_voxels"] == int(labels.sum())
    assert summary["spacing_mm"] == pytest.approx(list(SPACING_MM))
    assert summary["other_components_ml"] == [] and summary["cavities_filled_ml"] == 0.0
    assert_faithful(summary, label_ml)
    mesh = load_mesh(summary["out"])
    # the liver frame is the patient's: left-right the widest, then front-back, then height ...
    size = np.ptp(mesh.points, axis=0)
    assert size[0] > size[1] > size[2]
    assert size[0] * 1e3 == pytest.approx(2 * RADII_MM[0], abs=3 * SPACING_MM.max())
    # ... and the bump is on the left (+x), anterior (-y), superior (+z) side, wherever the file's axes ran
    top = mesh.points[mesh.points[:, 2] > np.quantile(mesh.points[:, 2], 0.9)]
    assert top[:, 0].mean() > 0.005 and top[:, 1].mean() < -0.002
    # the origin is the bounding box's centre, and the summary says where that lies in the scanner
    assert (mesh.bounds.sum(axis=0) / 2) == pytest.approx(np.zeros(3), abs=1e-9)
    lowest_lps = mesh.points.min(axis=0) * 1e3 + summary["lps_origin_mm"]
    assert lowest_lps == pytest.approx([-RADII_MM[0], -RADII_MM[1], -RADII_MM[2]], abs=3 * SPACING_MM.max())
    assert "superior" in summary["placement"] and "anterior" in summary["placement"]


def test_the_default_support_is_the_bare_area_superior_and_posterior(tmp_path):
    path, _ = lps_file(tmp_path)
    summary = build(tmp_path, path)
    (x, y, z, radius, stiffness), = summary["support_regions"]
    mesh = load_mesh(summary["out"])
    assert y > 0.0 and z > 0.0  # posterior, superior
    assert summary["support_skin_nodes"] >= 6 and stiffness > 0.0 and radius > 0.0
    assert "bare area" in summary["support"]
    held = np.linalg.norm(mesh.points[mesh.skin_nodes] - (x, y, z), axis=1) <= radius
    assert held.sum() == summary["support_skin_nodes"]
    assert read_support(support_path(summary["out"]))["support_regions"] == pytest.approx([x, y, z, radius, stiffness])
    # a demo on the mesh takes the file: its physics node and offline model hold the organ there
    demo = DemoMesh(tmp_path / "out" / "organ.msh")
    assert demo.physics_parameters(mesh)["support_regions"] == pytest.approx([x, y, z, radius, stiffness])
    held_regions = demo.model_params().support_regions
    assert len(held_regions) == 1 and held_regions[0] == pytest.approx((x, y, z, radius, stiffness))


def test_a_second_label_holds_the_organ_where_it_touches_it(tmp_path):
    # a vena cava: a vertical cylinder of radius 8 mm pressed into the organ's posterior, right side
    def cava(lps):
        return np.hypot(lps[:, 0] + 10.0, lps[:, 1] - 24.0) <= 8.0

    affine = grid_affine(SHAPE)
    path = write_nifti(tmp_path / "two.nii.gz", rasterise(SHAPE, affine, bumped_organ, cava), affine)
    summary = build(tmp_path, path, label=1, support_label=2)
    regions = np.array(summary["support_regions"])
    centres_lps = regions[:, :3] * 1e3 + summary["lps_origin_mm"]
    assert len(regions) >= 1 and summary["support_skin_nodes"] >= 3
    assert (centres_lps[:, 1] > 10.0).all()  # all posterior, where the cava lies
    assert np.abs(centres_lps[:, 0] + 10.0).max() < 20.0
    assert "label 2" in summary["support"]


def test_regions_given_replace_the_bare_area(tmp_path):
    path, _ = lps_file(tmp_path)
    # spheres of 1 cm over the organ's right and left ends, 3 cm from its centre (liver frame, m)
    regions = [(-0.03, 0.0, 0.0, 0.01, 2e6), (0.03, 0.0, 0.0, 0.01, 3e6)]
    summary = build(tmp_path, path, support_regions=regions)
    assert summary["support_regions"] == [list(region) for region in regions]
    assert "2 region(s) given with --support-regions" in summary["support"]
    assert read_support(support_path(summary["out"]))["support_regions"] == [v for region in regions for v in region]
    mesh = load_mesh(summary["out"])
    skin = mesh.points[mesh.skin_nodes]
    held = [np.linalg.norm(skin - region[:3], axis=1) <= region[3] for region in regions]
    assert held[0].any() and held[1].any()  # each end is held
    assert summary["support_skin_nodes"] == int((held[0] | held[1]).sum())


def test_regions_that_hold_no_skin_node_are_refused_and_nothing_is_written(tmp_path):
    path, _ = lps_file(tmp_path)
    with pytest.raises(ValueError, match=r"the support regions hold no skin node of the mesh \(support: 1 region"):
        build(tmp_path, path, support_regions=[(0.5, 0.5, 0.5, 0.01, 1e6)])
    assert list((tmp_path / "out").iterdir()) == []


def test_a_second_label_with_regions_or_the_organs_own_label_is_refused(tmp_path):
    path, _ = lps_file(tmp_path)
    with pytest.raises(ValueError, match=r"^give either --support-label or --support-regions, not both$"):
        build(tmp_path, path, support_label=2, support_regions=[(0.0, 0.0, 0.0, 0.01, 1e6)])
    with pytest.raises(ValueError, match=r"^--support-label 1 is the organ's own label"):
        build(tmp_path, path, label=1, support_label=1)
    assert list((tmp_path / "out").iterdir()) == []


def test_a_cut_off_organ_is_closed_and_the_faces_are_named(tmp_path):
    # the scan ends 12 mm below the top of the organ: the superior face of the volume cuts it
    shape = (100, 80, 17)
    affine = grid_affine(shape)
    affine[2, 3] = -RADII_MM[2] - 2 * SPACING_MM[2]  # k = 0 just below the organ, k = 16 at 12 mm
    labels = rasterise(shape, affine, organ)
    assert labels[:, :, -1].any()
    summary = build(tmp_path, write_nrrd(tmp_path / "cut.nrrd", labels, affine))
    assert summary["touched_faces"] == [f"k = {shape[2] - 1} (superior)"]
    assert "superior" in summary["warnings"][0] and "closed" in summary["warnings"][0]
    assert_faithful(summary, labels.sum() * voxel_ml(affine))
    mesh = load_mesh(summary["out"])
    assert mesh.watertight


#: A real liver mask, TotalSegmentator's (Apache-2.0; data/README.md): 3 mm voxels, cut off by the scan below and above.
REAL_LIVER = Path(__file__).parent / "data" / "totalsegmentator_example_liver.nii.gz"
#: The bound on a real liver's surface (voxels), looser than the synthetic shapes' (docs/segmentation.md#figures).
REAL_SURFACE_VOXELS = 4.0
#: The real liver's mesh, of the patient meshes' order (~30 k tets), where the bound no longer depends on decimation.
REAL_TARGET_TETS = 20000


def test_a_real_liver_mask_builds_a_sound_supported_liver_of_its_volume(tmp_path):
    summary = build_from_segmentation(REAL_LIVER, tmp_path / "out" / "liver.msh", target_tets=REAL_TARGET_TETS)
    assert summary["spacing_mm"] == pytest.approx([3.0, 3.0, 3.0]) and summary["axes"].startswith("RAS")
    assert summary["label_volume_ml"] == pytest.approx(summary["label_voxels"] * 0.027)
    assert 900.0 < summary["kept_volume_ml"] < summary["label_volume_ml"]  # an adult liver; specks dropped
    assert summary["mesh_volume_ml"] == pytest.approx(summary["kept_volume_ml"], rel=0.03)
    assert summary["max_surface_distance_voxels"] <= REAL_SURFACE_VOXELS
    assert summary["touched_faces"] == ["k = 0 (inferior)", "k = 29 (superior)"]  # the scan's ends
    assert summary["tetrahedra"] == pytest.approx(REAL_TARGET_TETS, rel=0.1)
    mesh = load_mesh(summary["out"])
    assert assert_sound(mesh) == 1
    assert summary["support_skin_nodes"] >= 6 and "bare area" in summary["support"]
    size = np.ptp(mesh.points, axis=0)
    assert size[0] > size[2] and 0.15 < size[0] < 0.30  # wider (left-right) than high, as a liver is


def test_two_blobs_keep_the_largest_and_report_the_other(tmp_path):
    # a small ball joined to it by a rod one voxel thin (a leak of the segmentation)
    def organ_and_balls(lps):
        near_ball = np.linalg.norm(lps - (-30.0, 0.0, 0.0), axis=-1) <= 7.0
        big = ((lps - (12.0, 0.0, 0.0)) / (24.0, 20.0, 16.0)) ** 2
        return (big.sum(axis=-1) <= 1.0) | near_ball

    shape = (110, 80, 22)
    affine = grid_affine(shape)
    labels = rasterise(shape, affine, organ_and_balls)
    ball_only = rasterise(shape, affine, lambda lps: np.linalg.norm(lps - (-30.0, 0.0, 0.0), axis=-1) <= 7.0)
    rod = np.zeros_like(labels)
    j, k = shape[1] // 2, shape[2] // 2
    between = np.flatnonzero(labels[:, j, k] == 0)
    rod[between[(between > np.flatnonzero(ball_only[:, j, k]).max()) & (between < 80)], j, k] = 1
    assert rod.sum() > 3  # the gap between the ball and the organ, bridged by one voxel per step
    summary = build(tmp_path, write_nifti(tmp_path / "blobs.nii.gz", labels | rod, affine))
    big_ml = (labels.sum() - ball_only.sum()) * voxel_ml(affine)
    assert summary["kept_volume_ml"] == pytest.approx(big_ml, rel=0.01)
    assert summary["other_components_ml"][0] == pytest.approx(ball_only.sum() * voxel_ml(affine), rel=0.1)
    assert_faithful(summary, summary["kept_volume_ml"])


def test_a_cavity_is_filled_and_reported(tmp_path):
    def hollow(lps):
        return organ(lps) & (np.linalg.norm(lps, axis=-1) > 8.0)

    affine = grid_affine(SHAPE)
    labels = rasterise(SHAPE, affine, hollow)
    solid = rasterise(SHAPE, affine, organ)
    summary = build(tmp_path, write_nrrd(tmp_path / "hollow.nrrd", labels, affine))
    cavity_ml = (solid.sum() - labels.sum()) * voxel_ml(affine)
    assert cavity_ml > 1.0
    assert summary["cavities_filled_ml"] == pytest.approx(cavity_ml, rel=0.05)
    assert_faithful(summary, solid.sum() * voxel_ml(affine))
    assert summary["kept_volume_ml"] == pytest.approx(solid.sum() * voxel_ml(affine), rel=0.01)


# --- refusals: one line on stderr naming the file and what to do, exit 2, nothing written ---------------------

def refused(tmp_path, capsys, path, *options):
    out = tmp_path / "out" / "organ.msh"
    status = main(["mesh", "build", str(path), "--target-tets", "2000", "--out", str(out), *options])
    error = [line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("[")]  # the bar
    assert status == 2
    assert len(error) == 1 and error[0].startswith("liver-sim: error: ")
    assert list((tmp_path / "out").iterdir()) == []  # no mesh, no support file, no temporary file
    return error[0]


def test_an_empty_volume_is_refused(tmp_path, capsys):
    affine = grid_affine((20, 20, 8))
    path = write_nifti(tmp_path / "empty.nii.gz", np.zeros((20, 20, 8), np.uint8), affine)
    assert "no labelled voxel" in refused(tmp_path, capsys, path)


def test_an_absent_label_is_refused_with_the_labels_present(tmp_path, capsys):
    path, _ = lps_file(tmp_path)
    error = refused(tmp_path, capsys, path, "--label", "7")
    assert "--label 7" in error and "label 1:" in error and " mL" in error


def test_several_labels_and_none_chosen_are_listed(tmp_path, capsys):
    affine = grid_affine(SHAPE)
    labels = rasterise(SHAPE, affine, bumped_organ, lambda lps: np.linalg.norm(lps, axis=-1) <= 5.0)
    error = refused(tmp_path, capsys, write_nifti(tmp_path / "two.nii.gz", labels, affine))
    assert "2 labels, choose one with --label N" in error
    assert f"label 1: {int((labels == 1).sum())} voxels" in error and "label 2:" in error


def test_a_volume_without_spacing_is_refused(tmp_path, capsys):
    path = tmp_path / "bare.nii.gz"
    nibabel.save(nibabel.Nifti1Image(np.ones((10, 10, 10), np.uint8), None), str(path))
    assert "no voxel spacing" in refused(tmp_path, capsys, path)
    spaceless = tmp_path / "bare.nrrd"
    nrrd.write(str(spaceless), np.ones((10, 10, 10), np.uint8))
    assert "no voxel spacing" in refused(tmp_path, capsys, spaceless)


def test_a_label_too_small_for_an_organ_is_refused(tmp_path, capsys):
    affine = grid_affine(SHAPE)
    labels = rasterise(SHAPE, affine, lambda lps: np.linalg.norm(lps, axis=-1) <= 6.0)
    assert "too small to be an organ" in refused(tmp_path, capsys, write_nrrd(tmp_path / "pea.nrrd", labels, affine))


def test_a_file_that_is_not_an_image_is_refused(tmp_path, capsys):
    path = tmp_path / "notes.nii.gz"
    path.write_text("not an image\n")
    assert "not a readable NIfTI image" in refused(tmp_path, capsys, path)
    nrrd_path = tmp_path / "notes.nrrd"
    nrrd_path.write_text("not an image\n")
    assert "not a readable NRRD image" in refused(tmp_path, capsys, nrrd_path)


def test_a_non_integer_volume_is_refused_and_whole_floats_are_taken(tmp_path, capsys):
    affine = grid_affine(SHAPE)
    labels = rasterise(SHAPE, affine, bumped_organ)
    ct = labels * 57.3 - 1000.0 + 0.25
    error = refused(tmp_path, capsys, write_nifti(tmp_path / "ct.nii.gz", ct.astype(np.float32), affine))
    assert "non-integer values" in error and "not the CT" in error
    summary = build(tmp_path, write_nifti(tmp_path / "float.nii.gz", labels.astype(np.float32), affine))
    assert summary["label_voxels"] == int(labels.sum())


def test_a_support_label_that_does_not_touch_is_refused(tmp_path, capsys):
    affine = grid_affine(SHAPE)
    labels = rasterise(SHAPE, affine, organ, lambda lps: np.linalg.norm(lps - (0.0, 0.0, 80.0), axis=-1) <= 60.0)
    labels[labels == 2] = 0
    labels[:3, :3, :3] = 2  # a far corner
    path = write_nifti(tmp_path / "apart.nii.gz", labels, affine)
    assert "does not touch the organ" in refused(tmp_path, capsys, path, "--label", "1", "--support-label", "2")


def test_the_command_prints_the_summary_and_writes_both_files(tmp_path, capsys):
    path, _ = lps_file(tmp_path)
    absent = tmp_path / "cases" / "patient.vtu"  # refused before the build, naming the folder
    assert main(["mesh", "build", str(path), "--target-tets", "3000", "--out", str(absent)]) == 2
    assert f"the folder {absent.parent} does not exist" in capsys.readouterr().err
    assert not absent.parent.exists()
    out = tmp_path / "out" / "patient.vtu"
    assert main(["mesh", "build", str(path), "--target-tets", "3000", "--out", str(out)]) == 0
    printed = capsys.readouterr()
    for word in ("voxels", "spacing 0.7 x 0.7 x 2.5 mm", "mL", "tetrahedra", "voxels (", "placement",
                 "bare area", " s"):
        assert word in printed.out
    assert "4/4 distance" in printed.err  # the progress bar's stages
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["patient.support.yaml", "patient.vtu"]
