"""Figures of a run: rates and period errors of arrivals, force smoothness (Fig. 8)."""
import numpy as np

from liver_sim.sessions.analysis import contact_fraction, largest_force_jump_n, rate_figures


def test_rate_figures_of_a_regular_stream_with_one_gap():
    arrival = np.concatenate([np.arange(100) * 1e-3, 0.105 + np.arange(100) * 1e-3])
    figures = rate_figures(arrival, 1000.0)
    assert figures["samples"] == 200
    assert np.isclose(figures["max_gap_s"], 0.006)
    assert np.isclose(figures["period_error_max_s"], 0.005)
    assert figures["period_error_p50_s"] < 1e-9
    assert np.isclose(figures["rate_hz"], 199 / (arrival[-1] - arrival[0]))


def test_largest_jump_counts_pairs_both_in_contact_or_with_onsets_either():
    forces = np.zeros((6, 3))
    forces[:, 2] = [0.0, 1.0, 1.1, 1.4, 0.0, 0.0]  # onset and release are not steady contact
    assert np.isclose(largest_force_jump_n(forces), 0.3)
    assert largest_force_jump_n(forces[:2]) == 0.0
    assert np.isclose(largest_force_jump_n(forces, onsets=True), 1.4)  # the release
    assert np.isclose(largest_force_jump_n(forces[:3], onsets=True), 1.0)  # the onset
    assert largest_force_jump_n(forces[4:], onsets=True) == 0.0  # out of contact on both sides
    assert contact_fraction(forces) == 0.5


def test_largest_jump_ignores_pairs_sent_further_apart_than_a_tick():
    forces = np.zeros((5, 3))
    forces[:, 0] = [1.0, 1.01, 1.5, 1.52, 1.53]
    sent = np.array([0.0, 0.001, 0.020, 0.021, 0.022])  # a 19 ms scheduling gap before the third
    assert np.isclose(largest_force_jump_n(forces), 0.49)
    assert np.isclose(largest_force_jump_n(forces, times_s=sent, max_period_s=0.0015), 0.02)


def test_the_offline_baseline_holds_the_newest_physics_force_between_frames():
    from haptic_bridge.parameters import BridgeParameters
    from liver_sim.sessions.analysis import held_wrench_baseline

    p = BridgeParameters.defaults()
    ticks = 1.0 + np.arange(2000) * 1e-3
    wrench_at = 1.0 + np.arange(0, 2.0, 1 / 150)
    wrench = np.zeros((len(wrench_at), 3))
    wrench[:, 2] = 0.5
    poses_at = ticks - 0.0002
    commands = held_wrench_baseline(ticks, wrench_at, wrench, poses_at, p)
    assert commands.shape == (2000, 3)
    assert np.all(commands[:, :2] == 0.0)
    # soft start and the rate limit ramp up to the held force, which is then held exactly
    assert commands[0, 2] < 0.5 and np.allclose(commands[-500:, 2], 0.5)
    # before any wrench arrived the baseline renders zero
    early = held_wrench_baseline(ticks[:5], wrench_at + 10.0, wrench, poses_at, p)
    assert np.all(early == 0.0)


def test_process_costs_are_shares_of_a_core_and_switches_per_second():
    import os

    from liver_sim.running.network import process_costs, process_counters

    now = process_counters(os.getpid())
    assert set(now) == {"cpu_s", "voluntary", "involuntary"} and now["cpu_s"] > 0.0
    assert process_counters(2 ** 22 + 12345) is None
    before = {"a": {"cpu_s": 1.0, "voluntary": 10, "involuntary": 2}, "gone": None}
    after = {"a": {"cpu_s": 1.5, "voluntary": 1010, "involuntary": 22}, "gone": None}
    assert process_costs(before, after, 2.0) == {"a": {"cpu_share_of_one_core": 0.25, "voluntary_switches_per_s": 500.0,
                                                       "involuntary_switches_per_s": 10.0}}


def test_fig8_figures_compare_the_held_force_with_the_rendered_one():
    from liver_sim.sessions.analysis import fig8_figures

    t = np.arange(300) * 1e-3
    rendered = np.zeros((300, 3))
    rendered[:, 2] = 0.2 + 2.0 * t                                    # a ramp at 1 kHz: 2 mN per tick
    held = rendered[(np.floor(t * 150) / 150 * 1000).astype(int)]     # held between 150 Hz updates
    figures = fig8_figures(rendered, held)
    assert np.isclose(figures["largest_jump_with_local_model_n"], 0.002)
    assert figures["largest_jump_without_local_model_n"] > 0.012      # steps of 6-7 ticks' worth
    assert np.isclose(figures["smoothness_ratio"], figures["largest_jump_without_local_model_n"] / 0.002)
    assert fig8_figures(held[:1], held)["smoothness_ratio"] is None   # nothing rendered: no ratio
    touch = np.zeros((340, 3))
    touch[40:, 2] = rendered[:, 2]                                    # the same, from touching the surface on
    touch_held = np.zeros((340, 3))
    touch_held[40:, 2] = held[:, 2]
    figures = fig8_figures(touch, touch_held)
    assert np.isclose(figures["largest_jump_without_local_model_n"], 0.2)  # the held force's step onto the surface
    assert np.isclose(figures["largest_jump_with_local_model_n"], 0.2)     # the rendered one's too: no ramp in
    assert figures["smoothness_ratio_steady"] > 6.0                        # in steady contact, the ramp's steps
