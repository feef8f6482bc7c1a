"""The device map: the haptic device's workspace (frame `phantom_base`) ↔ the liver frame, and its parameters.

One type and one parameter set serve every node that maps between the two frames: the tool node
(device samples → tool poses), the simulated PHANToM (script → hand target) and the haptic bridge
(liver-frame forces → device commands). Metres, newtons.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from liver_sim.base.checks import positive, vector3
from liver_sim.base.geometry.rotations import matrix_to_quaternion, quaternion_to_matrix
from liver_sim.base.parameters import Param, parameter_value, quaternion_parameter, vector_parameter

#: The device map's parameters, declared alike by every node that uses the map.
DEVICE_MAP_PARAMETERS = {
    "device_rotation_xyzw": Param([0.0, 0.0, 0.0, 1.0], "rotation R of the device→liver map "
                                  "p_liver = device_scale·R·p_device + device_translation_m, as a quaternion "
                                  "(x, y, z, w); forces get Rᵀ"),
    "device_translation_m": Param([0.0, 0.0, 0.0], "translation of the device→liver map: liver-frame position "
                                  "of the device origin (m)"),
    "device_scale": Param(1.0, "scale of the device→liver map (liver metres per device metre); forces are "
                          "not scaled", 0.01, 100.0),
}


def _rotation_matrix(rotation) -> np.ndarray:
    """A read-only proper rotation matrix from a 3×3 matrix or an (x, y, z, w) quaternion, or ValueError."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape == (4,):
        r = quaternion_to_matrix(r)
    elif r.shape != (3, 3) or not np.isfinite(r).all():
        raise ValueError(f"DeviceMap.rotation must be a finite 3x3 matrix or (x, y, z, w) quaternion, "
                         f"got shape {r.shape}")
    elif not (np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0.0):
        raise ValueError("DeviceMap.rotation must be a proper rotation (orthonormal, det +1)")
    r = np.array(r)
    r.setflags(write=False)
    return r


@dataclass(frozen=True, eq=False)
class DeviceMap:
    """Device workspace → liver frame: p_liver = scale·R·p_device + translation.

    `rotation` is a 3×3 matrix or a quaternion (x, y, z, w), `translation` is in metres, `scale`
    (> 0, dimensionless) multiplies device motion into liver motion. Forces are free vectors: they
    only rotate (by Rᵀ towards the device) and are not scaled, so a liver-side stiffness K (N/m) is
    felt at the device as K·scale N per metre of stylus motion — use that product in the passivity
    check. `workspace_radius_m` (m): a device sample farther than this from the device origin is
    implausible (:meth:`pose` refuses it).
    """

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    workspace_radius_m: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "rotation", _rotation_matrix(self.rotation))
        object.__setattr__(self, "translation", vector3(self.translation, "DeviceMap.translation"))
        object.__setattr__(self, "scale", positive(self.scale, "DeviceMap.scale"))
        object.__setattr__(self, "workspace_radius_m",
                           positive(self.workspace_radius_m, "DeviceMap.workspace_radius_m"))
        object.__setattr__(self, "_quaternion", tuple(matrix_to_quaternion(self.rotation).tolist()))
        object.__setattr__(self, "_scaled_rows", tuple(tuple(row) for row in (self.scale * self.rotation).tolist()))
        object.__setattr__(self, "_offset", tuple(self.translation.tolist()))

    def same_as(self, other: DeviceMap | None) -> bool:
        """Whether `other` maps every point and force as this map does (the workspace radius aside)."""
        return (other is not None and self.scale == other.scale and np.array_equal(self.rotation, other.rotation)
                and np.array_equal(self.translation, other.translation))

    @classmethod
    def from_parameters(cls, values, workspace_radius_m: float = 0.5) -> DeviceMap:
        """The map named by the DEVICE_MAP_PARAMETERS of `values` (a mapping or a node's record), or ValueError
        naming the bad parameter."""
        return cls(quaternion_parameter(values, "device_rotation_xyzw"),
                   vector_parameter(values, "device_translation_m", 3), parameter_value(values, "device_scale"),
                   workspace_radius_m)

    def device_to_liver(self, point: np.ndarray) -> np.ndarray:
        """Device point (m) → liver point (m): scale·R·p + translation."""
        return self.scale * (self.rotation @ point) + self.translation

    def device_to_liver_floats(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """:meth:`device_to_liver` of one point given as floats (a 1 kHz loop places each sample)."""
        (a, b, c), (d, e, f), (g, h, i) = self._scaled_rows
        tx, ty, tz = self._offset
        return a * x + b * y + c * z + tx, d * x + e * y + f * z + ty, g * x + h * y + i * z + tz

    def liver_to_device(self, point: np.ndarray) -> np.ndarray:
        """Liver point (m) → device point (m): Rᵀ·(p − translation)/scale."""
        return self.rotation.T @ (point - self.translation) / self.scale

    @property
    def liver_to_device_motion(self) -> np.ndarray:
        """Rᵀ/scale (3×3): a motion (m) in the liver frame → the stylus's in the device frame."""
        return self.rotation.T / self.scale

    def liver_to_device_force(self, force: np.ndarray) -> np.ndarray:
        """Force (N) in the liver frame → device frame: Rᵀ·F (rotation only, no scale)."""
        return self.rotation.T @ force

    def pose(self, position, orientation_xyzw) -> tuple[np.ndarray, np.ndarray]:
        """(liver position (m), liver orientation (x, y, z, w)) of one device sample (device frame, m).

        A sample farther than `workspace_radius_m` from the device origin, or with a non-finite
        or zero component, raises ValueError saying why.
        """
        position = np.asarray(position, dtype=np.float64)
        if not np.isfinite(position).all():
            raise ValueError(f"device position {position.tolist()} is not finite")
        distance = math.hypot(*position) if position.shape == (3,) else float(np.linalg.norm(position))
        if distance > self.workspace_radius_m:
            raise ValueError(f"device position {np.round(position, 4).tolist()} m is {distance:.3g} m from the "
                             f"device origin, beyond workspace_radius_m={self.workspace_radius_m:g}")
        return self.device_to_liver(position), self._liver_orientation(orientation_xyzw)

    def _liver_orientation(self, orientation_xyzw) -> np.ndarray:
        """q_map ⊗ q_device, normalised, w ≥ 0: the orientation R·R_device as a unit quaternion (x, y, z, w), in
        floats (a 1 kHz relay calls it per sample); a zero or non-finite quaternion is refused."""
        components = tuple(map(float, orientation_xyzw)) if len(orientation_xyzw) == 4 else ()
        norm = math.sqrt(sum(c * c for c in components)) if components else 0.0
        if not (math.isfinite(norm) and norm > 0.0):
            raise ValueError(f"quaternion must be a finite, non-zero (x, y, z, w), got {orientation_xyzw!r}")
        bx, by, bz, bw = (c / norm for c in components)
        ax, ay, az, aw = self._quaternion
        q = (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
             aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)
        length = math.sqrt(sum(c * c for c in q))
        sign = 1.0 if q[3] >= 0.0 else -1.0
        return np.array([sign * c / length for c in q])
