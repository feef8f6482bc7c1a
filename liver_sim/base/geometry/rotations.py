"""Rotations as 3×3 matrices and unit quaternions (x, y, z, w), shared by the physics, the bridge and the messages."""
import math

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


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a 3×3 rotation matrix (Shepperd's method, w ≥ 0)."""
    r = rotation
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s]
    q = np.array(q)
    return q if q[3] >= 0.0 else -q


def quaternion_from_z_axis(normal) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of the shortest rotation taking +z to the direction of `normal`
    (half a turn about x when `normal` points along −z). Floats: it runs for every published local model."""
    nx, ny, nz = (float(c) for c in normal)
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (math.isfinite(length) and length > 0.0):
        raise ValueError(f"normal must be non-zero and finite, got {[nx, ny, nz]}")
    nx, ny, nz = nx / length, ny / length, nz / length
    if 1.0 + nz < 1e-12:
        return (1.0, 0.0, 0.0, 0.0)
    qx, qy, qw = -ny, nx, 1.0 + nz
    norm = math.sqrt(qx * qx + qy * qy + qw * qw)
    return (qx / norm, qy / norm, 0.0, qw / norm)