"""Label volumes built in the tests: voxel grids in the patient's LPS axes (mm), shapes rasterised on them, and the
NIfTI (RAS affine) and NRRD (LPS space) files that hold them."""
import nibabel
import nrrd
import numpy as np

RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])


def centred_affine(shape, spacing_mm, rotation=np.eye(3)):
    """Voxel index → LPS (mm): `rotation` × the (anisotropic) spacing, centred on the origin."""
    affine = np.eye(4)
    affine[:3, :3] = rotation @ np.diag(spacing_mm)
    affine[:3, 3] = -affine[:3, :3] @ ((np.array(shape) - 1) / 2.0)
    return affine


def rasterise(shape, affine_lps, *shapes):
    """uint8 labels: label k + 1 where shapes[k] holds the voxel centre (later shapes win)."""
    index = np.indices(shape).reshape(3, -1).T.astype(float)
    lps = index @ affine_lps[:3, :3].T + affine_lps[:3, 3]
    labels = np.zeros(len(index), dtype=np.uint8)
    for value, inside in enumerate(shapes, start=1):
        labels[inside(lps)] = value
    return labels.reshape(shape)


def write_nifti(path, labels, affine_lps):
    """`labels` as a NIfTI image whose (RAS) affine is `affine_lps` (mm) with x and y negated."""
    nibabel.save(nibabel.Nifti1Image(labels, RAS_TO_LPS @ affine_lps), str(path))
    return path


def write_nrrd(path, labels, affine_lps):
    """`labels` as an NRRD in left-posterior-superior space with the directions and origin of `affine_lps` (mm)."""
    nrrd.write(str(path), labels, {"space": "left-posterior-superior", "space directions": affine_lps[:3, :3].T,
                                   "space origin": affine_lps[:3, 3]})
    return path
