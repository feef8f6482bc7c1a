"""haptic_bridge.safety: the norm clamp, the rate limit, the watchdog ramp, the soft start and their composition
SafeForceOutput."""
import math

import numpy as np
import pytest

from haptic_bridge.safety import (
    PHANTOM_MAX_FORCE_N,
    RateLimiter,
    SafeForceOutput,
    Watchdog,
    clamp_norm,
)

FRESH = (0.0, 0.0)
STALE = (0.2, 0.0)  # local model 200 ms old, lifetime 50 ms


def test_clamp_keeps_direction_and_limits_the_norm():
    force = np.array([3.0, 0.0, 4.0])  # 5 N
    clamped = clamp_norm(force, 2.0)
    np.testing.assert_allclose(clamped, [1.2, 0.0, 1.6])
    np.testing.assert_array_equal(force, [3.0, 0.0, 4.0])  # input untouched
    np.testing.assert_allclose(clamp_norm(np.array([0.3, -0.4, 0.0]), 2.0), [0.3, -0.4, 0.0])
    huge = clamp_norm(np.array([1e308, -1e308, 0.0]), 2.0)  # |F| overflows a naive norm
    np.testing.assert_allclose(huge, [np.sqrt(2.0), -np.sqrt(2.0), 0.0])


def test_a_clamped_force_is_never_above_the_clamp_however_its_norm_is_rounded():
    forces = np.random.default_rng(0).normal(scale=5.0, size=(20000, 3))
    clamped = np.array([clamp_norm(f, 2.0) for f in forces])
    assert np.linalg.norm(clamped, axis=1).max() <= 2.0
    assert max(math.hypot(*f) for f in clamped) <= 2.0
    assert np.linalg.norm(clamped, axis=1).max() == pytest.approx(2.0, abs=1e-9)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_clamp_turns_non_finite_into_zero(bad):
    np.testing.assert_array_equal(clamp_norm(np.array([1.0, bad, 0.0]), 2.0), np.zeros(3))


def test_rate_limiter_bounds_the_change_per_tick():
    limiter = RateLimiter(max_rate_n_per_s=200.0, period_s=0.001)  # 0.2 N per tick
    target = np.array([0.0, 3.0, 4.0])
    previous = np.zeros(3)
    for _ in range(30):
        out = limiter.step(target)
        assert np.linalg.norm(out - previous) <= 0.2 + 1e-12
        previous = out
    np.testing.assert_allclose(previous, target)  # 5 N reached after 25 ticks
    first = RateLimiter(200.0, 0.001).step(target)
    np.testing.assert_allclose(first, target / 25.0)  # moves straight towards the target


def test_rate_limiter_holds_per_second_of_tick_time_through_a_burst():
    limiter = RateLimiter(max_rate_n_per_s=400.0, period_s=0.001)
    target = np.array([0.0, 0.0, 2.0])
    times = [0.0, 0.001, 0.004, 0.004001, 0.004002, 0.005]  # a 3 ms gap, then two catch-up ticks 1 µs apart
    forces = [limiter.step(target, t) for t in times]
    np.testing.assert_allclose([f[2] for f in forces], [0.4, 0.8, 2.0, 2.0, 2.0, 2.0])  # first: one period
    limiter.reset()
    limiter.step(np.zeros(3), 0.0)
    burst = [limiter.step(target, 0.001 + k * 1e-6) for k in range(3)]  # three ticks within 3 µs of each other
    assert burst[-1][2] - burst[0][2] <= 400.0 * 2e-6 + 1e-12, "the burst adds no more than its span allows"


def test_rate_limiter_survives_a_non_finite_target():
    limiter = RateLimiter(200.0, 0.001)
    limiter.last = np.array([1.0, 0.0, 0.0])  # the force it sent last
    out = limiter.step(np.array([np.nan, 0.0, 0.0]))
    np.testing.assert_allclose(out, [0.8, 0.0, 0.0])  # heads for zero at the rate limit
    np.testing.assert_allclose(limiter.step(np.array([1.0, 0.0, 0.0])), [1.0, 0.0, 0.0])


def _ramp_up(watchdog):
    for _ in range(20):
        watchdog.update(*FRESH)
    assert watchdog.gain == 1.0 and watchdog.state == "ok"


def test_watchdog_reaches_exactly_zero_within_ten_ticks_and_stays_there():
    watchdog = Watchdog(lifetime_s=0.05, ramp_time_s=0.01, period_s=0.001)
    _ramp_up(watchdog)
    gains = [watchdog.update(*STALE) for _ in range(10)]
    assert gains[-1] == 0.0 and watchdog.state == "stale"
    assert all(a > b for a, b in zip(gains, gains[1:]))  # a ramp, not a step
    assert gains[0] < 1.0
    for _ in range(100):
        assert watchdog.update(*STALE) == 0.0
        assert watchdog.state == "stale"


def test_watchdog_states_and_ramp_back_up():
    watchdog = Watchdog()
    assert watchdog.state == "stale" and watchdog.gain == 0.0  # no data yet
    _ramp_up(watchdog)
    watchdog.update(*STALE)
    assert watchdog.state == "ramping_down" and 0.0 < watchdog.gain < 1.0
    for _ in range(10):
        watchdog.update(*STALE)
    assert watchdog.update(*FRESH) > 0.0 and watchdog.state == "ramping_up"
    gains = [watchdog.update(*FRESH) for _ in range(9)]
    assert watchdog.state == "ok" and gains[-1] == 1.0
    assert all(a < b for a, b in zip(gains, gains[1:]))
    assert gains[0] < 1.0


@pytest.mark.parametrize("model_age, pose_age, model_lifetime", [
    (0.06, 0.0, None),      # model older than the default lifetime
    (0.0, 0.06, None),      # tool pose older than its lifetime
    (np.inf, 0.0, None),    # never received
    (0.0, np.nan, None),
    (0.03, 0.0, 0.02),      # model older than the lifetime it carries
])
def test_watchdog_counts_each_stale_input(model_age, pose_age, model_lifetime):
    watchdog = Watchdog()
    _ramp_up(watchdog)
    for _ in range(10):
        watchdog.update(model_age, pose_age, model_lifetime)
    assert watchdog.gain == 0.0 and watchdog.state == "stale"


def test_watchdog_honours_a_longer_model_lifetime():
    watchdog = Watchdog()
    _ramp_up(watchdog)
    watchdog.update(0.08, 0.0, model_lifetime_s=0.1)
    assert watchdog.state == "ok"


@pytest.mark.parametrize("kwargs, name", [
    ({"max_force": 3.4}, "max_force"),
    ({"max_force": 0.0}, "max_force"),
    ({"max_force": np.nan}, "max_force"),
    ({"max_rate_n_per_s": -1.0}, "max_rate_n_per_s"),
    ({"max_rate_n_per_s": 100.0}, "max_rate_n_per_s"),  # cannot follow a 2 N → 0 ramp in 10 ms
    ({"period_s": 0.0}, "period_s"),
    ({"lifetime_s": -0.05}, "lifetime_s"),
    ({"ramp_time_s": 0.0}, "ramp_time_s"),
])
def test_safe_output_refuses_bad_parameters_by_name(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SafeForceOutput(**kwargs)


def test_safe_output_accepts_the_phantom_limit():
    assert SafeForceOutput(max_force=PHANTOM_MAX_FORCE_N, max_rate_n_per_s=400.0).max_force == 3.3


def test_safe_output_follows_a_steady_force_and_drops_to_zero_when_stale():
    output = SafeForceOutput(max_force=2.0, max_rate_n_per_s=400.0)
    force = np.array([0.0, 0.0, 1.5])
    for _ in range(30):
        out = output.step(force, *FRESH)
    np.testing.assert_allclose(out, force)
    assert output.state == "ok"
    outs = [output.step(force, *STALE) for _ in range(10)]
    np.testing.assert_array_equal(outs[-1], np.zeros(3))
    assert 0.0 < np.linalg.norm(outs[0]) < 1.5  # ramped, not cut
    for _ in range(50):
        np.testing.assert_array_equal(output.step(np.array([1.0, 1.0, 1.0]), *STALE), np.zeros(3))


def test_safe_output_releases_a_clamped_contact_without_delay():
    output = SafeForceOutput(max_force=2.0, max_rate_n_per_s=400.0)
    for _ in range(100):
        output.step(np.array([0.0, 0.0, 50.0]), *FRESH)  # far beyond the clamp
    out = output.step(np.zeros(3), *FRESH)
    assert np.linalg.norm(out) == pytest.approx(2.0 - 0.4)  # one rate step below the clamp


def test_safe_output_never_exceeds_the_clamp_or_emits_non_finite_values():
    rng = np.random.default_rng(20261122)
    output = SafeForceOutput(max_force=2.0, max_rate_n_per_s=400.0)
    specials = [np.nan, np.inf, -np.inf, 1e308, -1e308, 0.0]
    previous = np.zeros(3)
    for _ in range(5000):
        force = rng.normal(scale=10.0 ** rng.uniform(-3, 6), size=3)
        if rng.random() < 0.2:
            force[rng.integers(3)] = specials[rng.integers(len(specials))]
        model_age = [0.0, 0.01, 0.2, np.inf, np.nan][rng.integers(5)] if rng.random() < 0.3 else 0.0
        out = output.step(force, model_age, 0.0)
        assert out.shape == (3,)
        assert np.isfinite(out).all()
        assert np.linalg.norm(out) <= 2.0 * (1 + 1e-12)
        # The rate limit holds except for the cut to exactly zero at the end of a stale ramp.
        assert np.linalg.norm(out - previous) <= 0.4 * (1 + 1e-9) or not out.any()
        previous = out


def test_soft_start_rises_over_its_time_after_start_and_after_restart():
    output = SafeForceOutput(2.0, 400.0, 0.001, 0.05, 0.01, soft_start_s=0.1)
    force = np.array([0.0, 0.0, 1.0])
    outs = [float(np.linalg.norm(output.step(force, 0.0, 0.0))) for _ in range(150)]
    assert outs[9] < 0.11 and outs[49] == pytest.approx(0.5, abs=0.02) and outs[-1] == pytest.approx(1.0)
    output.restart()
    assert float(np.linalg.norm(output.step(force, 0.0, 0.0))) <= 0.011
    for _ in range(30):  # stale: down within ramp_time_s (10 ms)
        output.step(force, 1.0, 0.0)
    assert not output.step(force, 1.0, 0.0).any()
    rise = [float(np.linalg.norm(output.step(force, 0.0, 0.0))) for _ in range(100)]
    assert rise[19] < 0.25  # recovery ramps up as slowly as the start, not in 10 ms


def test_a_lowered_clamp_bounds_the_very_next_command():
    output = SafeForceOutput(2.0, 400.0, 0.001, 0.05, 0.01, soft_start_s=0.1)
    for _ in range(200):
        output.step(np.array([0.0, 0.0, 1.5]), 0.0, 0.0)
    output.configure(0.05, 400.0, 0.05, 0.01, 0.1)
    assert np.linalg.norm(output.step(np.array([0.0, 0.0, 1.5]), 0.0, 0.0)) <= 0.05
    with pytest.raises(ValueError, match="max_force"):
        output.configure(5.0, 400.0, 0.05, 0.01, 0.1)
    assert output.max_force == 0.05  # a refused change leaves the limits as they were
