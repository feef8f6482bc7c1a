"""Rotations shared by the physics core and the haptic bridge."""
import numpy as np


def quaternion_to_matrix(quaternion) -> np.ndarray:
    """3×3 rotation matrix of the quaternion (x, y, z, w); normalised first, refused if zero or non-finite."""
    q = np.asarray(quaternion, dtype=np.float64)
    norm = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
    if not (np.isfinite(norm) and norm > 0.0):
        raise ValueError(f"quaternion must be a finite, non-zero (x, y, z, w), got {quaternion!r}")
    x, y, z, w = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
