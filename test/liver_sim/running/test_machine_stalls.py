"""The machine-stall sentinel (liver_sim.running.machine_stalls): what it notes, and how a loop's gap is split between
the machine and the product."""
from __future__ import annotations

import io
import json

import numpy as np
import pytest

from liver_sim.running.machine_stalls import SENTINEL_PERIOD_S, STALL_S, gaps_with_stalls, read_stalls, watch


def test_the_sentinel_notes_a_late_wake_up_from_its_last_one_and_nothing_else():
    """A fake clock: on time for 5 wake-ups, then the machine gives the sentinel nothing for 9 ms."""
    now = [100.0]
    wakes = iter([0.0] * 5 + [0.009] + [0.0] * 5)

    def sleep(seconds):
        now[0] += seconds + next(wakes)

    out = io.StringIO()
    watch(out, lambda: len(out.getvalue()) > 0 and now[0] > 100.02, clock=lambda: now[0], sleep=sleep)
    stalls = [json.loads(line) for line in out.getvalue().splitlines()]
    assert len(stalls) == 1
    start, end = stalls[0]
    assert start == pytest.approx(100.0 + 5 * SENTINEL_PERIOD_S)
    assert end - start == pytest.approx(SENTINEL_PERIOD_S + 0.009) and end - start > STALL_S


def test_a_gap_is_split_into_the_machine_stall_inside_it_and_the_rest(tmp_path):
    times = np.concatenate([np.arange(0, 0.010, 0.001), [0.022], 0.022 + np.arange(1, 10) * 0.001, [0.040]])
    path = tmp_path / "stalls.jsonl"
    path.write_text("[0.012, 0.020]\n[0.5, 0.6]\n")
    other_cpu = tmp_path / "other.jsonl"
    other_cpu.write_text("[0.014, 0.019]\n")  # inside the first: counted once
    stalls = read_stalls([path, other_cpu], (0.0, 0.05))
    assert stalls.shape == (2, 2)
    first, second = gaps_with_stalls(times, 0.005, stalls)
    assert first["gap_s"] == pytest.approx(0.013) and first["machine_s"] == pytest.approx(0.008)
    assert first["product_s"] == pytest.approx(0.005)
    assert second["gap_s"] == pytest.approx(0.009) and second["machine_s"] == 0.0
    assert gaps_with_stalls(times, 0.02, stalls) == []
