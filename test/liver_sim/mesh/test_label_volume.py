"""Label volumes (label_volume.py): NIfTI and NRRD read into labels and the voxel → patient LPS (mm) affine, whichever
way the file writes its axes; the label chosen; every refusal naming the file. Volumes of a few voxels, built here."""
import math

import nibabel
import nrrd
import numpy as np
import pytest

from liver_sim.mesh.label_volume import LabelVolume, is_segmentation_path, read_label_volume, select_label
from liver_sim.mesh.tetmesh import MeshError

SHAPE = (3, 4, 5)
SPACING_MM = (0.7, 0.8, 2.5)
#: Voxel (0, 0, 0) in RAS (mm; +x right, +y anterior): 10 mm right, 20 mm posterior, 30 mm superior.
ORIGIN_RAS_MM = (10.0, -20.0, 30.0)
#: The same grid in LPS (+x left, +y posterior), worked out by hand: x and y change sign, origin and steps alike.
EXPECTED_AFFINE_LPS = np.array([[-0.7, 0.0, 0.0, -10.0],
                                [0.0, -0.8, 0.0, 20.0],
                                [0.0, 0.0, 2.5, 30.0],
                                [0.0, 0.0, 0.0, 1.0]])
#: The one labelled voxel, and where its centre lies in the patient (LPS, mm): RAS (11.4, -17.6, 40.0).
VOXEL = (2, 3, 4)
VOXEL_LPS_MM = (-11.4, 17.6, 40.0)


def one_voxel(dtype=np.uint8):
    labels = np.zeros(SHAPE, dtype=dtype)
    labels[VOXEL] = 1
    return labels


def ras_affine():
    affine = np.diag([*SPACING_MM, 1.0])
    affine[:3, 3] = ORIGIN_RAS_MM
    return affine


def nifti(tmp_path, labels=None, affine=None, name="mask.nii.gz"):
    path = tmp_path / name
    nibabel.save(nibabel.Nifti1Image(one_voxel() if labels is None else labels,
                                     ras_affine() if affine is None else affine), str(path))
    return path


def nrrd_in(space, directions, origin, name="mask.nrrd", labels=None, **fields):
    def write(tmp_path):
        path = tmp_path / name
        nrrd.write(str(path), one_voxel() if labels is None else labels,
                   {"space": space, "space directions": np.asarray(directions, float),
                    "space origin": np.asarray(origin, float), **fields})
        return path
    return write


WRITERS = {
    "NIfTI (RAS affine)": nifti,
    "NRRD right-anterior-superior": nrrd_in("right-anterior-superior", np.diag(SPACING_MM), ORIGIN_RAS_MM),
    "NRRD RAS": nrrd_in("RAS", np.diag(SPACING_MM), ORIGIN_RAS_MM),
    "NRRD left-posterior-superior": nrrd_in("left-posterior-superior", np.diag([-0.7, -0.8, 2.5]),
                                            (-10.0, 20.0, 30.0)),
    "Slicer .seg.nrrd, one layer": nrrd_in(
        "RAS", [[np.nan] * 3, *np.diag(SPACING_MM)], ORIGIN_RAS_MM, name="mask.seg.nrrd",
        labels=one_voxel()[None], Segment0_LabelValue="1", Segment0_Name="liver"),
}


@pytest.mark.parametrize("write", WRITERS.values(), ids=WRITERS.keys())
def test_every_file_puts_the_voxel_at_the_same_place_in_the_patient(tmp_path, write):
    volume = read_label_volume(write(tmp_path))
    assert volume.labels.shape == SHAPE
    assert [tuple(v) for v in np.argwhere(volume.labels == 1)] == [VOXEL]
    np.testing.assert_allclose(volume.affine_lps_mm, EXPECTED_AFFINE_LPS, atol=1e-12)
    np.testing.assert_allclose(volume.affine_lps_mm @ (*VOXEL, 1.0), (*VOXEL_LPS_MM, 1.0), atol=1e-12)
    np.testing.assert_allclose(volume.spacing_mm, SPACING_MM)
    assert volume.voxel_volume_mm3 == pytest.approx(0.7 * 0.8 * 2.5)


def test_the_axes_say_how_the_file_wrote_them_and_slicer_names_its_segments(tmp_path):
    assert read_label_volume(nifti(tmp_path)).axes == "RAS (NIfTI affine)"
    lps = read_label_volume(WRITERS["NRRD left-posterior-superior"](tmp_path))
    assert lps.axes == "left-posterior-superior (NRRD space)" and lps.names == {}
    slicer = read_label_volume(WRITERS["Slicer .seg.nrrd, one layer"](tmp_path))
    assert slicer.names == {1: "liver"}
    assert slicer.describe(1, 1000) == 'label 1 "liver": 1000 voxels, 1.4 mL'  # 1000 × 1.4 mm³
    assert slicer.describe(2, 10) == "label 2: 10 voxels, 0.014 mL"


def test_an_oblique_grid_keeps_its_spacing_and_voxel_volume(tmp_path):
    angle = math.radians(30.0)
    turn = np.array([[math.cos(angle), -math.sin(angle), 0.0], [math.sin(angle), math.cos(angle), 0.0], [0, 0, 1]])
    affine = ras_affine()
    affine[:3, :3] = turn @ np.diag(SPACING_MM)
    volume = read_label_volume(nifti(tmp_path, affine=affine, name="oblique.nii"))
    np.testing.assert_allclose(volume.spacing_mm, SPACING_MM)
    assert volume.voxel_volume_mm3 == pytest.approx(1.4)
    # the first voxel step: 0.7 mm along the turned x axis of RAS, i.e. (-cos, -sin, 0) × 0.7 in LPS
    np.testing.assert_allclose(volume.affine_lps_mm[:3, 0], [-0.7 * math.cos(angle), -0.7 * math.sin(angle), 0.0])


def test_a_trailing_single_dimension_is_dropped(tmp_path):
    volume = read_label_volume(nifti(tmp_path, labels=one_voxel()[..., None]))
    assert volume.labels.shape == SHAPE


def test_whole_floats_become_integer_labels(tmp_path):
    labels = one_voxel(np.float32) * 3.0
    volume = read_label_volume(nifti(tmp_path, labels=labels, name="float.nii"))
    assert volume.labels.dtype.kind == "i" and volume.labels[VOXEL] == 3 and volume.labels.sum() == 3


def refusal(path):
    with pytest.raises(MeshError) as caught:
        read_label_volume(path)
    assert str(caught.value).startswith(f"{path}: ") and caught.value.source == str(path)
    return caught.value.defect


def test_missing_files_folders_and_other_formats_are_refused(tmp_path):
    assert refusal(tmp_path / "absent.nii.gz") == "no such file"
    (tmp_path / "folder.nrrd").mkdir()
    assert refusal(tmp_path / "folder.nrrd") == "not a regular file"
    (tmp_path / "mask.png").write_bytes(b"\x89PNG")
    assert refusal(tmp_path / "mask.png").startswith("not a label volume (readable: .nii .nii.gz .nrrd")


def test_a_probability_map_is_refused_naming_a_fractional_voxel(tmp_path):
    labels = np.zeros(SHAPE, np.float32)
    labels[1, 2, 3] = 0.5
    defect = refusal(nifti(tmp_path, labels=labels, name="probability.nii.gz"))
    assert defect.startswith("not a label volume: 1 voxels hold non-integer values (e.g. 0.5 at voxel (1, 2, 3))")


def test_an_image_that_is_not_three_dimensional_is_refused(tmp_path):
    defect = refusal(nifti(tmp_path, labels=np.ones((4, 5), np.uint8), name="slice.nii"))
    assert defect.startswith("a 2-D image of shape (4, 5)")


def test_an_nrrd_whose_space_is_not_the_patients_is_refused(tmp_path):
    path = nrrd_in("scanner-xyz", np.diag(SPACING_MM), (0, 0, 0), name="scanner.nrrd")(tmp_path)
    assert refusal(path) == "space 'scanner-xyz' is not patient axes (e.g. left-posterior-superior)"


def test_overlapping_segment_layers_are_refused(tmp_path):
    layers = np.stack([one_voxel(), one_voxel()])
    path = nrrd_in("RAS", [[np.nan] * 3, *np.diag(SPACING_MM)], ORIGIN_RAS_MM, name="layers.seg.nrrd",
                   labels=layers)(tmp_path)
    assert refusal(path).startswith("2 layers of overlapping segments")


def test_a_zero_voxel_step_is_refused(tmp_path):
    path = nrrd_in("RAS", np.diag([0.7, 0.0, 2.5]), ORIGIN_RAS_MM, name="flat.nrrd")(tmp_path)
    assert refusal(path).startswith("unusable voxel spacing or directions in the header")


def memory_volume(labels):
    """Voxels of 1 × 1 × 2 mm: 500 voxels hold 1 mL."""
    return LabelVolume(np.asarray(labels), np.diag([1.0, 1.0, 2.0, 1.0]), "case.nii", "RAS (NIfTI affine)", {})


def test_the_only_label_is_chosen_and_a_named_label_is_selected():
    labels = np.zeros(SHAPE, np.int16)
    labels[0, :2] = 4  # 10 voxels
    assert select_label(memory_volume(labels), None)[0] == 4
    labels[2, 3, :3] = 1  # 3 voxels
    label, mask = select_label(memory_volume(labels), 1)
    assert label == 1 and mask.dtype == bool
    assert [tuple(v) for v in np.argwhere(mask)] == [(2, 3, 0), (2, 3, 1), (2, 3, 2)]


def test_the_choice_is_refused_with_the_labels_present_counted_and_measured():
    labels = np.zeros(SHAPE, np.int16)
    labels[0, :2] = 4
    labels[2, 3, :3] = 1
    volume = memory_volume(labels)
    present = "label 1: 3 voxels, 0.006 mL; label 4: 10 voxels, 0.02 mL"
    with pytest.raises(MeshError) as several:
        select_label(volume, None)
    assert str(several.value) == f"case.nii: 2 labels, choose one with --label N ({present})"
    with pytest.raises(MeshError) as absent:
        select_label(volume, 7)
    assert str(absent.value) == f"case.nii: --label 7: no voxel has label 7; choose one of: {present}"
    with pytest.raises(MeshError, match=r"^case\.nii: no labelled voxel"):
        select_label(memory_volume(np.zeros(SHAPE, np.uint8)), None)


@pytest.mark.parametrize("big", [7, 70_000], ids=["bincount", "unique"])
def test_label_counts_count_every_non_zero_label(big):
    labels = np.zeros(SHAPE, np.int32)
    labels[0, 0, :3] = big
    labels[1, 1, :2] = 2
    assert memory_volume(labels).label_counts() == {2: 2, big: 3}
    labels[2, 2, 2] = -1
    assert memory_volume(labels).label_counts() == {-1: 1, 2: 2, big: 3}


@pytest.mark.parametrize("name, readable", [("liver.nii", True), ("LIVER.NII.GZ", True), ("a.seg.nrrd", True),
                                            ("a.nhdr", True), ("liver.gz", False), ("liver.stl", False),
                                            ("nii", False)])
def test_segmentation_paths_are_told_by_their_suffix(name, readable):
    assert is_segmentation_path(f"/cases/{name}") is readable
