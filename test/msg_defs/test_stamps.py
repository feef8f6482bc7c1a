"""msg_defs.stamps: times and durations of seconds to builtin_interfaces/Time and Duration and back, to the
nanosecond, and their refusals naming the argument; the stamps a message builder takes, and Headers."""
import pytest
from builtin_interfaces.msg import Duration, Time
from std_msgs.msg import Header

from msg_defs import cdr
from msg_defs.stamps import (
    duration_msg,
    duration_parts,
    header_msg,
    seconds_from_stamp,
    stamp_from_seconds,
    stamp_parts,
    stamp_s_from_bytes,
)


def test_stamp_round_trip_to_the_nanosecond():
    stamp = stamp_from_seconds(1_700_000_000.25)
    assert (stamp.sec, stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert seconds_from_stamp(stamp_from_seconds(12.345678901)) == pytest.approx(12.345678901, abs=1e-9)
    carried = stamp_from_seconds(2.9999999999)
    assert (carried.sec, carried.nanosec) == (3, 0)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), 2.0 ** 31])
def test_stamp_refuses_negative_non_finite_and_overflowing_times(bad):
    with pytest.raises(ValueError, match="stamp"):
        stamp_from_seconds(bad)


def test_a_stamp_is_rounded_to_the_nearest_nanosecond():
    assert stamp_from_seconds(5.0000000004) == Time(sec=5, nanosec=0)
    assert stamp_from_seconds(5.0000000006) == Time(sec=5, nanosec=1)
    assert stamp_from_seconds(0.0) == Time(sec=0, nanosec=0)
    assert stamp_from_seconds(2.0 ** 31 - 1.0) == Time(sec=2 ** 31 - 1, nanosec=0)  # the last second sec can hold


def test_a_duration_is_parts_of_seconds_and_its_refusal_names_the_argument():
    assert duration_parts(0.0215, "lifetime_s") == (0, 21_500_000)
    assert duration_msg(3.25, "lifetime_s") == Duration(sec=3, nanosec=250_000_000)
    assert seconds_from_stamp(duration_msg(0.05, "lifetime_s")) == pytest.approx(0.05, abs=1e-12)
    for bad in (-1e-9, float("nan"), float("inf")):
        with pytest.raises(ValueError, match=r"^lifetime_s must be finite and in \[0, 2\*\*31\) s"):
            duration_msg(bad, "lifetime_s")


def test_a_builders_stamp_may_be_a_time_a_pair_or_seconds():
    assert stamp_parts(Time(sec=7, nanosec=8)) == (7, 8)
    assert stamp_parts((7, 8)) == (7, 8)
    assert stamp_parts(7.5) == (7, 500_000_000)
    with pytest.raises(ValueError, match="^stamp must be finite"):
        stamp_parts(-7.5)
    for stamp in (Time(sec=7, nanosec=500_000_000), (7, 500_000_000), 7.5):
        assert header_msg(stamp, "liver") == Header(stamp=Time(sec=7, nanosec=500_000_000), frame_id="liver")


def test_the_seconds_of_a_serialized_stamp():
    data = cdr.encode(1_700_000_000, 250_000_000, "liver", (0.0,) * cdr.WRENCH_FIELDS)
    assert stamp_s_from_bytes(data, "WrenchStamped") == pytest.approx(1_700_000_000.25, abs=1e-6)
