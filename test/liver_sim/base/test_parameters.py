"""The typed parameter records (liver_sim.base.parameters.parameter_record): a wrong name, type or range fails
where the values are read."""
import dataclasses

import pytest

from liver_sim.base.parameters import Param, parameter_record

TABLE = {"rate_hz": Param(150.0, "rate (Hz)", 1.0, 1000.0), "mode": Param("press", "mode", choices=("press", "cut")),
         "position_m": Param([0.0, 0.0, 0.0], "position (m)"), "on": Param(False, "switch"),
         "count": Param(3, "count", 0, 10)}
Record = parameter_record("Record", TABLE)


def test_a_record_holds_typed_values():
    record = Record.from_values({"rate_hz": 100, "mode": "cut", "position_m": [1, 2, 3], "on": True, "count": 4})
    assert record.rate_hz == 100.0 and isinstance(record.rate_hz, float)
    assert record.position_m == (1.0, 2.0, 3.0) and record.mode == "cut" and record.on and record.count == 4
    assert Record.defaults() == Record(**{name: spec.default for name, spec in TABLE.items()})
    assert [f.name for f in dataclasses.fields(Record)] == list(TABLE)


def test_a_record_is_frozen_and_replace_checks():
    record = Record.defaults()
    with pytest.raises(dataclasses.FrozenInstanceError):
        record.rate_hz = 1.0
    assert record.replace(rate_hz=30).rate_hz == 30.0 and record.rate_hz == 150.0
    assert record.as_dict()["mode"] == "press"
    with pytest.raises(ValueError, match="unknown parameter.*rate_hzz"):
        record.replace(rate_hzz=30)


@pytest.mark.parametrize("values, message", [
    ({"rate_hzz": 1.0}, "unknown parameter.*rate_hzz"),
    ({"mode": "press"}, "missing parameter.*count, on, position_m, rate_hz"),
])
def test_unknown_and_missing_names_are_refused_at_construction(values, message):
    full = {**Record.defaults().as_dict(), **values} if "rate_hzz" in values else values
    with pytest.raises(ValueError, match=message):
        Record.from_values(full)


@pytest.mark.parametrize("name, value, message", [
    ("rate_hz", 0.5, r"rate_hz=0.5 is outside"), ("mode", "grasp", "must be one of"),
    ("count", 2.5, "must be a int"), ("on", 1, "must be a bool"), ("position_m", "up", "must be a list"),
])
def test_wrong_types_and_ranges_are_refused(name, value, message):
    with pytest.raises(ValueError, match=message):
        Record.defaults().replace(**{name: value})
