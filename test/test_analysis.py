"""Figures of a run: rates and period errors of arrivals, force smoothness (Fig. 8)."""
import numpy as np

from liver_sim.analysis import contact_fraction, largest_force_jump_n, rate_figures


def test_rate_figures_of_a_regular_stream_with_one_gap():
    arrival = np.concatenate([np.arange(100) * 1e-3, 0.105 + np.arange(100) * 1e-3])
    figures = rate_figures(arrival, 1000.0)
    assert figures["samples"] == 200
    assert np.isclose(figures["max_gap_s"], 0.006)
    assert np.isclose(figures["period_error_max_s"], 0.005)
    assert figures["period_error_p50_s"] < 1e-9
    assert np.isclose(figures["rate_hz"], 199 / (arrival[-1] - arrival[0]))


def test_largest_jump_counts_only_pairs_both_in_contact():
    forces = np.zeros((6, 3))
    forces[:, 2] = [0.0, 1.0, 1.1, 1.4, 0.0, 0.0]  # onset and release are not steady contact
    assert np.isclose(largest_force_jump_n(forces), 0.3)
    assert largest_force_jump_n(forces[:2]) == 0.0
    assert contact_fraction(forces) == 0.5


def test_largest_jump_ignores_pairs_sent_further_apart_than_a_tick():
    forces = np.zeros((5, 3))
    forces[:, 0] = [1.0, 1.01, 1.5, 1.52, 1.53]
    sent = np.array([0.0, 0.001, 0.020, 0.021, 0.022])  # a 19 ms scheduling gap before the third
    assert np.isclose(largest_force_jump_n(forces), 0.49)
    assert np.isclose(largest_force_jump_n(forces, times_s=sent, max_period_s=0.0015), 0.02)
