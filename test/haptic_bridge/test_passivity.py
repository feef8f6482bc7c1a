"""haptic_bridge.passivity: the observer's pairing of motion with the command in effect at the device, the
controller on measured motion only, and the windowed judgement of generated energy on synthetic traces."""
import math

import numpy as np
import pytest

from haptic_bridge.passivity import (
    GENERATED_LIMIT_J,
    LATENCY_SMOOTHING,
    WINDOW_S,
    GenerationMonitor,
    PassivityObserver,
    max_generated_energy,
)

#: The samples' period (s): 1 kHz.
T = 0.001


def test_the_observer_pairs_each_motion_with_the_command_in_effect_at_the_device():
    """The motion between two samples meets the newest command sent at or before the later stamp minus the
    measured latency: with no latency the command sent just before, with 2 ms of latency the one before that."""
    def energy(latency_s: float) -> float:
        observer = PassivityObserver(T)
        observer.commanded(0.9995, np.zeros(3))
        observer.sample(1.000, 1.000 + latency_s, (0.0, 0.0, 0.0))
        observer.commanded(1.0005, np.array([0.0, 0.0, 1.0]))
        observer.sample(1.001, 1.001 + latency_s, (0.0, 0.0, 0.001))  # moved 1 mm along +z
        return observer.energy_j

    assert energy(0.0) == pytest.approx(0.001)   # the 1 N command acted over that millimetre: 1 mJ to the hand
    assert energy(0.002) == pytest.approx(0.0)   # it had not reached the device yet: the zero acted


def test_the_observer_counts_each_sample_once_and_only_forward():
    observer = PassivityObserver(T)
    observer.commanded(0.0, np.array([1.0, 0.0, 0.0]))
    observer.sample(0.001, 0.001, (0.0, 0.0, 0.0))
    observer.sample(0.002, 0.002, (0.002, 0.0, 0.0))
    observer.sample(0.002, 0.003, (0.002, 0.0, 0.0))   # the same sample read again
    observer.sample(0.0015, 0.003, (0.9, 0.0, 0.0))    # an older one
    assert observer.energy_j == pytest.approx(0.002)
    observer.forget_motion()                           # stale: no motion counted across the hole
    observer.sample(0.010, 0.010, (1.0, 1.0, 1.0))
    assert observer.energy_j == pytest.approx(0.002)


def test_the_controller_damps_measured_motion_only_and_only_what_the_contact_gave_back():
    """α = (E − E(t0))/(T·|v|²), v the measured stylus velocity, at most the cap; a still stylus gets nothing."""
    def controlled(excess_j: float, velocity_m_s: float, cap: float = 20.0, control: bool = True):
        observer = PassivityObserver(T, control=control, max_damping_ns_per_m=cap)
        observer.sample(0.0, 0.0, (0.0, 0.0, 0.0))
        observer.sample(0.001, 0.001, (0.0, 0.0, velocity_m_s * 0.001))
        observer.energy_j = observer.episode_energy_j + excess_j
        return observer.damp(np.array([0.0, 0.0, 1.0])), observer.damping_ns_per_m

    force, alpha = controlled(0.0006, 1.0)  # 0.6 mJ given back beyond what was put in, moving at 1 m/s
    assert alpha == pytest.approx(0.6) and force == pytest.approx([0.0, 0.0, 0.4])
    assert controlled(0.0006, 0.0) == (pytest.approx([0.0, 0.0, 1.0]), 0.0), "a still stylus: no controller force"
    assert controlled(-0.001, 1.0) == (pytest.approx([0.0, 0.0, 1.0]), 0.0), "covered by what the hand put in"
    assert controlled(0.0006, 1.0, control=False) == (pytest.approx([0.0, 0.0, 1.0]), 0.0)
    force, alpha = controlled(0.0006, 1.0, cap=0.5)
    assert alpha == 0.5 and force == pytest.approx([0.0, 0.0, 0.5])


def _trace(*segments):
    """(energy J, episode energy J) of consecutive (samples, energy at the end, in contact) segments at 1 kHz,
    energy moving linearly within each."""
    energy, episode, e, e0 = [], [], 0.0, 0.0
    for samples, end, contact in segments:
        for value in np.linspace(e, end, samples + 1)[1:]:
            if not contact:
                e0 = value
            energy.append(value)
            episode.append(e0)
        e = end
    return np.array(energy), np.array(episode)


def _generated(*segments) -> float:
    energy, episode = _trace(*segments)
    return float(max_generated_energy(energy, episode, round(WINDOW_S / T)).max())


def test_a_passive_press_and_release_generates_nothing():
    # the hand puts 2 mJ into a contact, which gives back 1.5 mJ (the rest dissipated), then lets go
    assert _generated((200, 0.0, False), (300, -0.002, True), (300, -0.0005, True), (200, -0.0005, False)) <= 1e-12


def test_energy_put_in_early_does_not_hide_energy_generated_later():
    """The old judgement (the running total never above 1 mJ) called this passive: 5 mJ absorbed by a first contact
    hid the 1 mJ a second contact generated seconds later."""
    segments = ((100, 0.0, False), (400, -0.005, True), (100, -0.005, False), (2000, -0.005, False),
                (300, -0.005, True), (300, -0.004, True), (100, -0.004, False))
    energy, _ = _trace(*segments)
    assert energy.max() <= 0.001  # passive by the old, running-total judgement
    assert _generated(*segments) == pytest.approx(0.001)


def test_a_contact_generating_slowly_within_a_window_is_caught_and_outside_it_is_not_summed():
    # 0.3 mJ generated in each of two contacts 2 s apart: no window holds more than 0.3 mJ
    segments = ((100, 0.0, False), (200, 0.0003, True), (2000, 0.0003, False), (200, 0.0006, True))
    assert _generated(*segments) == pytest.approx(0.0003)
    assert GENERATED_LIMIT_J > 0.0003 and _generated((100, 0.0, False), (400, 0.0008, True)) > GENERATED_LIMIT_J


def test_the_monitor_folds_what_the_loop_recorded_into_the_largest_window():
    monitor = GenerationMonitor(T)
    energy, episode = _trace((100, 0.0, False), (400, -0.002, True), (100, -0.002, False), (300, -0.001, True))
    in_contact = np.r_[np.zeros(100, bool), np.ones(400, bool), np.zeros(100, bool), np.ones(300, bool)]
    for k, (e, contact) in enumerate(zip(energy, in_contact)):
        monitor.record(k * T, float(e), bool(contact))
        if k % 250 == 0:
            monitor.update()
    assert monitor.update() == pytest.approx(0.001) and monitor.at_s == pytest.approx(899 * T)


def test_the_latency_is_the_arrival_minus_the_stamp_smoothed_and_never_negative():
    observer = PassivityObserver(T)
    assert math.isnan(observer.report()["device_latency_s"])  # no sample yet
    observer.sample(1.000, 1.010, (0.0, 0.0, 0.0))
    assert observer.latency_s == pytest.approx(0.010)           # the first sample's own
    observer.sample(1.001, 1.031, (0.0, 0.0, 0.0))              # 30 ms this time: moved a fraction of the way
    smoothed = 0.010 + LATENCY_SMOOTHING * (0.030 - 0.010)
    assert observer.latency_s == pytest.approx(smoothed)
    observer.sample(1.002, 1.001, (0.0, 0.0, 0.0))              # arrived "before" its stamp: counted as 0
    assert observer.latency_s == pytest.approx(smoothed * (1.0 - LATENCY_SMOOTHING))
    observer.sample(0.5, 0.52, (0.0, 0.0, 0.0))                 # the device's clock stepped back: anew
    assert observer.latency_s == pytest.approx(0.02)
    assert observer.report()["device_latency_s"] == pytest.approx(0.02)
