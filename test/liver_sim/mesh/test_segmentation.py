"""One label to a tet mesh (segmentation.py, mesh_from_label): small balls on anisotropic grids built here, in memory.
The mesh keeps the solid's volume and boundary, sits in the liver frame centred on its bounding box, reports the
parts it dropped, the cavities it filled and the faces of the scan that cut it, by the patient's side."""
import numpy as np
import pytest
from label_volumes import rasterise

from liver_sim.mesh.label_volume import LabelVolume
from liver_sim.mesh.segmentation import STAGES, boundary_quads, mesh_from_label
from liver_sim.mesh.tetmesh import MeshError

#: Voxel steps (mm): i runs to the patient's right (-x in LPS), j posterior, k superior.
STEPS_MM = np.array([-1.0, 1.2, 2.0])
ORIGIN_LPS_MM = np.array([100.0, -50.0, 20.0])
SHAPE = (46, 38, 26)
#: The ball's centre in the patient (LPS, mm): voxel (23, 19, 13).
CENTRE_INDEX = np.array([23, 19, 13])
CENTRE_LPS_MM = ORIGIN_LPS_MM + STEPS_MM * CENTRE_INDEX
#: 19 mm, an organ's size: the slices of 2 mm cut the ball's poles at 18 mm from its centre, in discs of 6 mm radius.
RADIUS_MM = 19.0
TARGET_TETS = 3000


def affine(steps_mm=STEPS_MM):
    matrix = np.diag([*steps_mm, 1.0])
    matrix[:3, 3] = ORIGIN_LPS_MM
    return matrix


def ball(centre_mm, radius_mm):
    return lambda lps: np.linalg.norm(lps - centre_mm, axis=-1) <= radius_mm


def volume(shape, steps_mm=STEPS_MM):
    """A LabelVolume of SHAPE whose voxels hold label 1 where `shape` holds their centres (LPS, mm)."""
    grid = affine(steps_mm)
    return LabelVolume(rasterise(SHAPE, grid, shape), grid, "case.nii", "LPS", {})


def voxel_ml(steps_mm=STEPS_MM):
    return float(np.prod(np.abs(steps_mm))) / 1e3


def build(label_volume, progress=None):
    return mesh_from_label(label_volume, 1, label_volume.labels == 1, TARGET_TETS, progress)


@pytest.fixture(scope="module")
def ball_built():
    """(volume, built, progress reports) of the ball."""
    ball_volume = volume(ball(CENTRE_LPS_MM, RADIUS_MM))
    stages = []
    return ball_volume, build(ball_volume, lambda step, total, text: stages.append((step, total, text))), stages


def test_a_ball_keeps_its_volume_and_boundary_and_is_centred_on_its_bounding_box(ball_built):
    ball_volume, built, stages = ball_built
    assert stages == [(1, 4, "components"), (2, 4, "surface"), (3, 4, "tetrahedra"), (4, 4, "distance")]
    assert [text for *_, text in stages] == list(STAGES)
    voxels = int((ball_volume.labels == 1).sum())
    assert built.label_voxels == voxels
    assert built.label_volume_ml == pytest.approx(voxels * voxel_ml())
    # the opening trims single voxels off the surface: the solid kept is the label but for a few of them
    assert built.kept_volume_ml == pytest.approx(built.kept_mask.sum() * voxel_ml())
    assert built.kept_volume_ml == pytest.approx(voxels * voxel_ml(), rel=0.01)
    assert built.other_components_ml == () and built.cavities_ml == 0.0
    assert built.touched_faces == () and built.warnings == ()
    mesh = built.mesh
    assert mesh.source == "case.nii label 1" and mesh.watertight
    assert mesh.volume * 1e6 == pytest.approx(built.kept_volume_ml, rel=0.03)
    assert len(mesh.tets) == pytest.approx(TARGET_TETS, rel=0.1)
    assert mesh.bounds.sum(axis=0) == pytest.approx(np.zeros(3), abs=1e-12)
    # the bounding box of a ball is centred on the ball: within a voxel of its centre in the patient
    assert built.lps_origin_mm == pytest.approx(CENTRE_LPS_MM, abs=np.abs(STEPS_MM).max())
    skin_radii_mm = np.linalg.norm(mesh.points[mesh.skin_nodes], axis=1) * 1e3
    assert np.abs(skin_radii_mm - RADIUS_MM).max() <= 1.5 * np.abs(STEPS_MM).max()
    assert 0.0 < built.max_distance_voxels <= 1.5
    assert 0.0 < built.max_distance_mm <= 1.5 * np.abs(STEPS_MM).max()


def test_voxel_indices_go_to_the_liver_frame_in_metres(ball_built):
    _, built, _ = ball_built
    grid = affine()
    at = lambda *index: built.to_liver_frame_m(np.array([index], dtype=float), grid)[0]  # noqa: E731
    assert at(*CENTRE_INDEX) == pytest.approx(np.zeros(3), abs=np.abs(STEPS_MM).max() / 1e3)
    # ten steps along i: 10 mm to the right (-x); along j: 12 mm posterior (+y); along k: 20 mm superior (+z)
    centre = at(*CENTRE_INDEX)
    assert at(*(CENTRE_INDEX + (10, 0, 0))) - centre == pytest.approx([-0.010, 0.0, 0.0], abs=1e-12)
    assert at(*(CENTRE_INDEX + (0, 10, 0))) - centre == pytest.approx([0.0, 0.012, 0.0], abs=1e-12)
    assert at(*(CENTRE_INDEX + (0, 0, 10))) - centre == pytest.approx([0.0, 0.0, 0.020], abs=1e-12)


def test_other_parts_are_dropped_and_reported_and_a_cavity_is_filled():
    outer, inner = ball(CENTRE_LPS_MM, RADIUS_MM), ball(CENTRE_LPS_MM, 9.0)
    speck = ball(ORIGIN_LPS_MM + STEPS_MM * (4, 4, 3), 3.0)  # 11 mm from the ball's surface
    built = build(volume(lambda lps: (outer(lps) & ~inner(lps)) | speck(lps)))
    speck_voxels, cavity_voxels, solid_voxels = (volume(shape).labels.sum() for shape in (speck, inner, outer))
    assert speck_voxels > 0 and cavity_voxels > 0
    assert built.other_components_ml == pytest.approx((speck_voxels * voxel_ml(),))
    assert built.cavities_ml == pytest.approx(cavity_voxels * voxel_ml(), rel=0.1)
    assert built.kept_volume_ml == pytest.approx(solid_voxels * voxel_ml(), rel=0.01)
    # one solid: the mesh fills the cavity (3.1 mL of 28.7) and leaves the speck out
    assert built.mesh.volume * 1e6 == pytest.approx(solid_voxels * voxel_ml(), rel=0.03)
    assert built.mesh.watertight and np.ptp(built.mesh.points, axis=0).max() * 1e3 < 2 * RADIUS_MM + 4


def test_a_ball_whose_poles_are_single_voxels_is_one_part():
    # 14 mm on slices of 2 mm: the slices through the poles hold one voxel each, joined to the ball along the coarse
    # axis that the opening's cross leaves out; they are trimmed off its surface, not parts of their own
    poles = volume(ball(CENTRE_LPS_MM, 14.0))
    labels = poles.labels
    assert [int(labels[:, :, k].sum()) for k in (6, 20)] == [1, 1]
    built = build(poles)
    assert built.other_components_ml == ()
    assert built.kept_volume_ml == pytest.approx(labels.sum() * voxel_ml(), rel=0.02)


def test_a_ball_cut_by_the_scan_is_closed_and_the_face_named_by_the_patients_side():
    # voxel i = 0 lies furthest left (steps to the right): a ball reaching past it is cut on its left
    cut = volume(ball(ORIGIN_LPS_MM + STEPS_MM * (8, 19, 13), RADIUS_MM))
    built = build(cut)
    assert built.touched_faces == ("i = 0 (left)",)
    assert built.warnings == ("label 1 touches the volume's i = 0 (left) face(s): the organ is cut off by the scan "
                              "there; built as a closed organ, flat where the scan ends",)
    assert built.mesh.watertight
    flipped = volume(ball(ORIGIN_LPS_MM + (8, 19 * 1.2, 26.0), RADIUS_MM), steps_mm=np.abs(STEPS_MM))
    assert build(flipped).touched_faces == ("i = 0 (right)",)


@pytest.mark.parametrize("radius_mm, steps_mm, defect", [
    (5.0, STEPS_MM, r"too small to be an organ: its largest part spans .* mm \(\d+ voxels\), an organ 20-500 mm; "
                    r"choose the organ's label with --label"),
    (19.0 * 20, STEPS_MM * 20, r"too large for an organ: .* mm; check the voxel spacing in the header"),
])
def test_a_label_not_the_size_of_an_organ_is_refused_naming_file_and_label(radius_mm, steps_mm, defect):
    centre = ORIGIN_LPS_MM + steps_mm * CENTRE_INDEX
    with pytest.raises(MeshError, match=rf"^case\.nii \(label 1\): {defect}"):
        build(volume(ball(centre, radius_mm), steps_mm=steps_mm))


def quad_areas(quads):
    return np.linalg.norm(np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0]), axis=1)


def test_one_voxels_boundary_is_the_six_faces_of_its_unit_cube():
    mask = np.zeros((3, 3, 3), bool)
    mask[1, 2, 0] = True  # on the array's edge: still closed
    quads = boundary_quads(mask)
    assert quads.shape == (6, 4, 3)
    corners = {tuple(c) for c in quads.reshape(-1, 3).tolist()}
    assert corners == {(1 + dx, 2 + dy, dz) for dx in (-0.5, 0.5) for dy in (-0.5, 0.5) for dz in (-0.5, 0.5)}
    np.testing.assert_allclose(quad_areas(quads), 1.0)
    # each face is flat across one axis, at ±0.5 from the voxel's centre
    flat = np.ptp(quads, axis=1) == 0
    assert (flat.sum(axis=1) == 1).all() and sorted(flat.argmax(axis=1)) == [0, 0, 1, 1, 2, 2]


@pytest.mark.parametrize("voxels, faces", [([(0, 0, 0), (1, 0, 0)], 10), ([(0, 0, 0), (1, 0, 0), (1, 1, 0)], 14),
                                           ([(0, 0, 0), (1, 1, 1)], 12)])
def test_faces_between_two_voxels_of_the_mask_are_not_boundary(voxels, faces):
    mask = np.zeros((2, 2, 2), bool)
    mask[tuple(np.array(voxels).T)] = True
    assert len(boundary_quads(mask)) == faces
