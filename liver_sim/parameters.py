"""Node parameter declarations without ROS: name → default, description with unit, range or choices.

The nodes declare them through rclpy (liver_sim.nodes.common.declare_parameters); offline runs
(liver_sim.sessions) read and check the same tables, so both refuse the same values.
"""
from __future__ import annotations

from dataclasses import dataclass


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
    return Param(default, "SCHED_FIFO priority (1-99) of the node's threads (its rate loop and the DDS threads "
                 "that feed it), as haptic and control loops run; 0 = normal scheduling. Needs CAP_SYS_NICE or "
                 "an rtprio limit (limits.conf); without it the node warns and runs with normal scheduling",
                 0, 99)


def check_parameter(name: str, spec: Param, value):
    """`value` if it lies in the range and choices of `spec`, else ValueError naming the parameter."""
    if spec.low is not None and not (spec.low <= value <= spec.high):
        raise ValueError(f"parameter {name}={value!r} is outside [{spec.low}, {spec.high}]")
    if spec.choices and value not in spec.choices:
        raise ValueError(f"parameter {name}={value!r} must be one of {spec.choices}")
    return value
