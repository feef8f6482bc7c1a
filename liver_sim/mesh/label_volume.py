"""Label volumes in: a segmentation's voxels and where they lie in the patient (docs/segmentation.md).

:func:`read_label_volume` reads NIfTI (``.nii``, ``.nii.gz``; nibabel) and NRRD (``.nrrd``, ``.nhdr``, 3D Slicer's
``.seg.nrrd``; pynrrd) into a :class:`LabelVolume`: whole-number labels per voxel and the affine from voxel indices
(i, j, k) to the patient's LPS coordinates in millimetres (+x left, +y posterior, +z superior, as DICOM).  NIfTI's
affine is RAS, so x and y change sign; an NRRD's ``space`` names its axes.  :func:`select_label` picks the voxels of
one label.  Every refused input raises :class:`MeshError` naming the file and saying what to do.
"""
from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from liver_sim.mesh.tetmesh import MeshError

NIFTI_SUFFIXES = (".nii", ".nii.gz")
NRRD_SUFFIXES = (".nrrd", ".nhdr", ".seg.nrrd")
SEGMENTATION_SUFFIXES = NIFTI_SUFFIXES + NRRD_SUFFIXES
#: Sign of each LPS axis along an NRRD ``space`` axis letter's positive direction.
_LPS_SIGN = {"left": (0, 1.0), "right": (0, -1.0), "posterior": (1, 1.0), "anterior": (1, -1.0),
             "superior": (2, 1.0), "inferior": (2, -1.0)}
_SPACE_ABBREVIATIONS = {"LPS": "left-posterior-superior", "RAS": "right-anterior-superior",
                        "LAS": "left-anterior-superior"}


@dataclass(frozen=True, eq=False)
class LabelVolume:
    """Labels (I, J, K) of whole numbers, and `affine_lps_mm` (4, 4): voxel index (i, j, k, 1) → patient LPS (mm).

    `names` maps a label to its segment's name when the file gives one (a Slicer .seg.nrrd); `axes` says how the
    file wrote its patient axes (e.g. "RAS (NIfTI)")."""

    labels: np.ndarray
    affine_lps_mm: np.ndarray
    source: str
    axes: str
    names: dict

    @property
    def spacing_mm(self) -> np.ndarray:
        """(3,) mm: the length of one voxel step along i, j and k."""
        return np.linalg.norm(self.affine_lps_mm[:3, :3], axis=0)

    @property
    def voxel_volume_mm3(self) -> float:
        """mm³ of one voxel: |det| of the affine's 3 × 3 part."""
        return float(abs(np.linalg.det(self.affine_lps_mm[:3, :3])))

    def label_counts(self) -> dict[int, int]:
        """{label: voxel count} of every non-zero label present."""
        flat = self.labels.ravel()
        low, high = int(flat.min()), int(flat.max())
        if low >= 0 and high < 1 << 16:  # bincount: a pass over the voxels, no sort
            counts = np.bincount(flat, minlength=high + 1)
            return {int(v): int(counts[v]) for v in np.flatnonzero(counts) if v != 0}
        values, counts = np.unique(flat, return_counts=True)
        return {int(v): int(c) for v, c in zip(values, counts) if v != 0}

    def describe(self, label: int, voxels: int) -> str:
        """'label 1 "liver": 1234 voxels, 56.7 mL'."""
        name = f' "{self.names[label]}"' if label in self.names else ""
        return f"label {label}{name}: {voxels} voxels, {voxels * self.voxel_volume_mm3 / 1e3:.4g} mL"


def is_segmentation_path(path) -> bool:
    """Whether `path`'s name ends in one of :data:`SEGMENTATION_SUFFIXES`."""
    return Path(path).name.lower().endswith(SEGMENTATION_SUFFIXES)


def read_label_volume(path) -> LabelVolume:
    """The label volume of a NIfTI or NRRD file; MeshError (file, defect, what to do) when refused."""
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise MeshError(source, "no such file" if not path.exists() else "not a regular file")
    if not is_segmentation_path(path):
        raise MeshError(source, f"not a label volume (readable: {' '.join(SEGMENTATION_SUFFIXES)})")
    if path.name.lower().endswith(NIFTI_SUFFIXES):
        labels, affine, axes, names = _read_nifti(path)
    else:
        labels, affine, axes, names = _read_nrrd(path)
    spacing = np.linalg.norm(affine[:3, :3], axis=0)
    if not (np.isfinite(affine).all() and (spacing > 0).all() and abs(np.linalg.det(affine[:3, :3])) > 0):
        raise MeshError(source, f"unusable voxel spacing or directions in the header ({_matrix(affine[:3, :3])}): "
                                "write the image with its spacing and orientation")
    return LabelVolume(_whole_numbers(source, labels), affine, source, axes, names)


def select_label(volume: LabelVolume, label: int | None) -> tuple[int, np.ndarray]:
    """(label, mask): the voxels of `label`, or of the only non-zero label when `label` is None.

    MeshError when no voxel is labelled, when `label` is absent, or when several labels are present and none was
    chosen; each message lists the labels with their voxel counts and volumes."""
    counts = volume.label_counts()
    present = "; ".join(volume.describe(value, count) for value, count in sorted(counts.items()))
    if not counts:
        raise MeshError(volume.source, "no labelled voxel (every voxel is 0): is this the segmentation file?")
    if label is None:
        if len(counts) > 1:
            raise MeshError(volume.source, f"{len(counts)} labels, choose one with --label N ({present})")
        label = next(iter(counts))
    elif label not in counts:
        raise MeshError(volume.source, f"--label {label}: no voxel has label {label}; choose one of: {present}")
    return label, volume.labels == label


def _read_nifti(path: Path) -> tuple[np.ndarray, np.ndarray, str, dict]:
    """Labels and LPS affine of a NIfTI-1/2 image (its RAS affine with x and y negated)."""
    import nibabel  # this reader's own library: the other mesh commands never need it

    source = str(path)
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            image = nibabel.load(source)
            header = image.header
            if int(header["qform_code"]) == 0 and int(header["sform_code"]) == 0:
                raise MeshError(source, "no voxel spacing or orientation in the header (qform_code and sform_code "
                                        "are 0): save the segmentation with the CT's affine (3D Slicer, or "
                                        "nibabel.Nifti1Image(labels, ct.affine))")
            labels = np.asanyarray(image.dataobj)
    except MeshError:
        raise
    except Exception as exc:  # nibabel's ImageFileError, a truncated gzip, a bad header …
        raise MeshError(source, f"not a readable NIfTI image ({_short(exc)}): give a .nii or .nii.gz label "
                                "volume") from None
    affine_ras = np.asarray(image.affine, dtype=np.float64)
    return _three_d(source, labels), np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine_ras, "RAS (NIfTI affine)", {}


def _read_nrrd(path: Path) -> tuple[np.ndarray, np.ndarray, str, dict]:
    """Labels and LPS affine of an NRRD (space directions and origin, in its ``space``); Slicer segment names."""
    import nrrd  # pynrrd: this reader's own library

    source = str(path)
    try:
        labels, header = nrrd.read(source)
    except Exception as exc:  # NRRDError, a bad encoding, a truncated file …
        raise MeshError(source, f"not a readable NRRD image ({_short(exc)}): give a .nrrd or .seg.nrrd label "
                                "volume") from None
    directions = header.get("space directions")
    space = _SPACE_ABBREVIATIONS.get(str(header.get("space", "")), str(header.get("space", "")))
    if directions is None or not space:
        raise MeshError(source, "no voxel spacing or orientation in the header (needs 'space' and 'space "
                                "directions'): save the segmentation from 3D Slicer or with the CT's geometry")
    directions = np.asarray(directions, dtype=np.float64)
    spatial = np.isfinite(directions).all(axis=1)
    if labels.ndim == 4 and spatial.sum() == 3 and labels.shape[int(np.argmin(spatial))] == 1:
        labels = labels.take(0, axis=int(np.argmin(spatial)))  # a Slicer segmentation with a single layer
        directions = directions[spatial]
    elif labels.ndim == 4:
        raise MeshError(source, f"{labels.shape[int(np.argmin(spatial))]} layers of overlapping segments: export "
                                "the segment as a labelmap (3D Slicer: Export to labelmap) and give that file")
    to_lps = np.zeros((3, 3))
    parts = space.lower().split("-")
    if len(parts) != 3 or any(part not in _LPS_SIGN for part in parts):
        raise MeshError(source, f"space '{space}' is not patient axes (e.g. left-posterior-superior)")
    for column, part in enumerate(parts):
        row, sign = _LPS_SIGN[part]
        to_lps[row, column] = sign
    affine = np.eye(4)
    affine[:3, :3] = to_lps @ directions.T  # space directions: one row per voxel axis
    affine[:3, 3] = to_lps @ np.asarray(header.get("space origin", np.zeros(3)), dtype=np.float64)
    names = {}
    for key, value in header.items():
        if key.startswith("Segment") and key.endswith("_LabelValue"):
            with contextlib.suppress(ValueError):
                names[int(value)] = header.get(key.replace("_LabelValue", "_Name"), "")
    return _three_d(source, labels), affine, f"{space} (NRRD space)", {k: v for k, v in names.items() if v}


def _three_d(source: str, labels: np.ndarray) -> np.ndarray:
    """The array as (I, J, K), trailing single dimensions dropped; MeshError for anything else."""
    while labels.ndim > 3 and labels.shape[-1] == 1:
        labels = labels[..., 0]
    if labels.ndim != 3:
        raise MeshError(source, f"a {labels.ndim}-D image of shape {labels.shape}: a label volume is 3-D")
    return labels


def _whole_numbers(source: str, labels: np.ndarray) -> np.ndarray:
    """Integer labels; a float volume whose values are all whole numbers is converted, any other refused."""
    if labels.dtype.kind in "iu":
        return labels
    if labels.dtype.kind == "b":
        return labels.view(np.uint8)
    if labels.dtype.kind != "f":
        raise MeshError(source, f"voxel type {labels.dtype} is not a label type: give an integer label volume")
    fractional = ~np.isfinite(labels) | (labels != np.round(labels))
    if fractional.any():
        where = tuple(int(v) for v in np.argwhere(fractional)[0])
        raise MeshError(source, f"not a label volume: {int(fractional.sum())} voxels hold non-integer values "
                                f"(e.g. {float(labels[where]):g} at voxel {where}); give the segmentation, not the "
                                "CT or a probability map (threshold it first)")
    return labels.astype(np.int32)


def _matrix(matrix: np.ndarray) -> str:
    return "[" + "; ".join(" ".join(f"{v:.4g}" for v in row) for row in matrix) + "]"


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:160]
