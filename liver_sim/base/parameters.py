"""Node parameter declarations without ROS: name → default, description with unit, range or choices.

The nodes declare them through rclpy (liver_sim.nodes.parameters.declare_parameters); offline runs
(liver_sim.sessions) read and check the same tables, so both refuse the same values. List values
(vectors, quaternions) are read through vector_parameter and quaternion_parameter.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Param:
    """A declared parameter: default, description (with its unit) and optional range or choices."""

    default: object
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple | None = None


def realtime_priority_parameter(default: int) -> Param:
    """The `realtime_priority` parameter of a node whose loop keeps a rate."""
    return Param(default, "SCHED_FIFO priority (1-99) of the node's rate loop thread (and the bridge's supervisor), "
                 "as haptic and control loops run; DDS, executor and diagnostics threads stay at normal priority "
                 "beside the rig's own processes; 0 = normal scheduling. Needs CAP_SYS_NICE or an rtprio limit "
                 "(limits.conf); without it the node warns and its loop runs with normal scheduling", 0, 99)


def check_parameter(name: str, spec: Param, value):
    """`value` if it lies in the range and choices of `spec`, else ValueError naming the parameter."""
    if spec.low is not None and not (spec.low <= value <= spec.high):
        raise ValueError(f"parameter {name}={value!r} is outside [{spec.low}, {spec.high}]")
    if spec.choices and value not in spec.choices:
        raise ValueError(f"parameter {name}={value!r} must be one of {spec.choices}")
    return value


def vector_parameter(values: dict, name: str, length: int) -> np.ndarray:
    """Parameter `name` of `values` as a finite float array of `length`, or ValueError naming it."""
    vector = np.asarray(values[name], dtype=np.float64)
    if vector.shape != (length,) or not np.isfinite(vector).all():
        raise ValueError(f"parameter {name} must be {length} finite numbers, got {values[name]!r}")
    return vector


def quaternion_parameter(values: dict, name: str) -> np.ndarray:
    """Parameter `name` of `values` as a finite, non-zero (x, y, z, w) quaternion, or ValueError naming it."""
    quaternion = vector_parameter(values, name, 4)
    if not np.linalg.norm(quaternion) > 0.0:
        raise ValueError(f"parameter {name} must be a non-zero quaternion (x, y, z, w), got {values[name]!r}")
    return quaternion
