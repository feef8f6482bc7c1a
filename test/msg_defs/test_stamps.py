"""msg_defs.stamps: times of seconds to builtin_interfaces/Time and back, to the nanosecond, and their refusals."""
import pytest

from msg_defs.stamps import seconds_from_stamp, stamp_from_seconds


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
