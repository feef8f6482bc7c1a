"""Node parameter declarations without ROS: name → default, description with unit, range or choices.

The nodes declare them through rclpy (liver_sim.nodes.parameters.declare_parameters); offline runs
(liver_sim.sessions) read and check the same tables, so both refuse the same values. List values
(vectors, quaternions) are read through vector_parameter and quaternion_parameter.

`parameter_record(name, table)` builds the typed record of a table: a frozen dataclass with one field per
parameter, whose construction refuses an unknown or a missing name, a value of another type than its default's
and a value outside its range or choices, so that a wrong name fails where the values are read (a node's start, a
test), not where a loop uses them.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, make_dataclass
from typing import ClassVar

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


def typed_value(name: str, default, value):
    """`value` in the type of `default` (an integer is taken for a float, a list's items are typed as its first
    item), or ValueError naming `name`."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, (list, tuple)):
        ok = isinstance(value, Sequence) and not isinstance(value, str)
        if ok and default:
            value = [typed_value(name, default[0], v) for v in value]
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ValueError(f"parameter {name}={value!r} must be a {type(default).__name__} like its default "
                         f"{default!r}")
    return value


class ParameterRecord:
    """The base of the records `parameter_record` builds: `PARAMETERS` is their table.

    Construction (`Record(**values)` or `Record.from_values(values)`) types each value as its default
    (typed_value; a list becomes a tuple) and checks it (check_parameter); a name the table does not declare, or
    one it declares and the values lack, is a ValueError naming it."""

    PARAMETERS: ClassVar[dict[str, Param]] = {}

    def __post_init__(self) -> None:
        for name, spec in self.PARAMETERS.items():
            value = check_parameter(name, spec, typed_value(name, spec.default, getattr(self, name)))
            object.__setattr__(self, name, tuple(value) if isinstance(value, list) else value)

    @classmethod
    def from_values(cls, values: Mapping[str, object]):
        """The record of `values` ({name: value}): every declared name, no other."""
        unknown = sorted(set(values) - set(cls.PARAMETERS))
        missing = sorted(set(cls.PARAMETERS) - set(values))
        if unknown or missing:
            raise ValueError(f"{cls.__name__}: " + "; ".join(
                text for text in (f"unknown parameter(s) {', '.join(unknown)}" if unknown else "",
                                  f"missing parameter(s) {', '.join(missing)}" if missing else "") if text))
        return cls(**values)

    @classmethod
    def take(cls, values):
        """The record of this table's names among `values`: a mapping or a record that holds them with others (a
        node's parameters, of which this table is a part); a name it lacks: ValueError."""
        source = values.as_dict() if isinstance(values, ParameterRecord) else values
        missing = sorted(set(cls.PARAMETERS) - set(source))
        if missing:
            raise ValueError(f"{cls.__name__}: missing parameter(s) {', '.join(missing)}")
        return cls(**{name: source[name] for name in cls.PARAMETERS})

    @classmethod
    def defaults(cls):
        """The record of the table's defaults."""
        return cls.from_values({name: spec.default for name, spec in cls.PARAMETERS.items()})

    def replace(self, **changes):
        """A checked copy with some values changed (an undeclared name: ValueError)."""
        return self.from_values({**self.as_dict(), **changes})

    def as_dict(self) -> dict:
        """{name: value} of every parameter."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def parameter_record(name: str, table: dict[str, Param], doc: str | None = None) -> type:
    """The frozen dataclass `name` (a ParameterRecord) with one field per parameter of `table`, typed as its
    default (a list default: a tuple), none of them optional."""
    record = make_dataclass(
        name, [(key, tuple if isinstance(spec.default, list) else type(spec.default)) for key, spec in table.items()],
        bases=(ParameterRecord,), frozen=True, namespace={"PARAMETERS": dict(table)})
    record.__doc__ = doc or f"The parameters of {name} (liver_sim.base.parameters.ParameterRecord)."
    return record


def parameter_value(values, name: str):
    """Parameter `name` of `values`: a {name: value} mapping or a typed record."""
    return values[name] if isinstance(values, Mapping) else getattr(values, name)


def vector_parameter(values, name: str, length: int) -> np.ndarray:
    """Parameter `name` of `values` (a mapping or a record) as a finite float array of `length`, or ValueError
    naming it."""
    vector = np.asarray(parameter_value(values, name), dtype=np.float64)
    if vector.shape != (length,) or not np.isfinite(vector).all():
        raise ValueError(f"parameter {name} must be {length} finite numbers, got {parameter_value(values, name)!r}")
    return vector


def quaternion_parameter(values, name: str) -> np.ndarray:
    """Parameter `name` of `values` (a mapping or a record) as a finite, non-zero (x, y, z, w) quaternion, or
    ValueError naming it."""
    quaternion = vector_parameter(values, name, 4)
    if not np.linalg.norm(quaternion) > 0.0:
        raise ValueError(f"parameter {name} must be a non-zero quaternion (x, y, z, w), got "
                         f"{parameter_value(values, name)!r}")
    return quaternion
