"""Multi-interval imaging: unbiased for steady light (length bias), adaptive K where light changes."""

import numpy as np
import pytest

from viform.imaging.multi_interval import multi_interval_image, multi_interval_rate, spike_ticks_around
from viform.light.scenes import StepScene, StillScene
from viform.sensors.spike import SpikeSensor
from viform.stream.container import SpikeStream


def test_spikes_around_an_instant_nearest_first_and_end_markers():
    spikes = np.zeros((30, 1, 2), bool)
    spikes[[2, 9, 10, 20, 25], 0, 0] = True
    stream = SpikeStream(spikes, 1000.0)
    prev, nxt = spike_ticks_around(stream, 10, 3, 3, lookahead_ticks=2)
    assert prev[:, 0].tolist() == [10, 9, 2] and nxt[:, 0].tolist() == [20, 25, 30]
    assert prev[:, 1].tolist() == [-1, -1, -1] and nxt[:, 1].tolist() == [30, 30, 30]


@pytest.mark.parametrize("shape", [(70, 80), (9, 13)], ids=["whole-words", "partial-word"])
def test_spikes_around_equal_brute_force_across_slabs_and_a_subset(shape):
    """The compiled collection (8 pixels a word, 4,096 a slab) against brute force: K spikes a side,
    nearest first, end markers, any chunking, and only the wanted pixels searched."""
    rng = np.random.default_rng(7)
    n, pixels = 300, shape[0] * shape[1]
    spikes = rng.random((n, pixels)) < rng.choice([0.0, 2e-3, 0.02, 0.3, 1.0], size=pixels)
    stream = SpikeStream(spikes.reshape(n, *shape), 1000.0)
    wanted = np.flatnonzero(rng.random(pixels) < 0.6)
    for tick, before, after, look in [(0, 1, 4, 1), (150, 4, 4, None), (299, 3, 2, 7), (77, 2, 5, 300)]:
        prev, nxt = spike_ticks_around(stream, tick, before, after, look, pixels_wanted=wanted)
        for j in range(pixels):
            if j not in wanted:
                assert (prev[:, j] == -1).all() and (nxt[:, j] == n).all()
                continue
            ticks = np.flatnonzero(spikes[:, j])
            p = ticks[ticks <= tick][::-1][:before]
            q = ticks[ticks > tick][:after]
            assert prev[:, j].tolist() == p.tolist() + [-1] * (before - p.size), (tick, j)
            assert nxt[:, j].tolist() == q.tolist() + [n] * (after - q.size), (tick, j)


@pytest.mark.parametrize("q, rate_per_tick", [(1.0, 0.02), (100.0, 0.05), (10_000.0, 0.3)])
def test_unbiased_for_steady_light_from_q_1_to_10_thousand(q, rate_per_tick):
    """n·Q/X with X the span of n = 2K − 1 intervals holding the instant: X ~ Gamma(nQ + 1, λ), E = λ.

    Tolerance: 5σ of the mean over pixels, σ = √(1/(nQ − 1) + rounding) / √pixels, where
    rounding moves the span by < 1 tick (sd ≤ ½ tick over n/rate ticks); plus a rounding
    bias: only the interval holding the instant is picked ∝ its length in ticks, its tick
    neighbours are not, which can shift the span by up to var(m)/μ ≤ ¼ tick² / μ, twice
    over with the neighbours' negative correlation: ≤ rate/(2n) relative. At Q = 1 the
    estimator that drops the length-biased interval (X ~ Gamma(nQ)) would read n·Q/(n·Q − 1)
    = 1.25× too bright: far outside the tolerance.
    """
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    electrons_per_s = rate_per_tick * q * sensor.parameters.clock_hz
    lux = sensor.parameters.optics.lux_from_electrons_per_s(electrons_per_s)
    side = 64
    n = 5
    ticks = int(12 * n / rate_per_tick)
    stream = sensor.capture(StillScene(np.full((side, side), lux)), ticks / sensor.parameters.clock_hz, seed=21)
    rate, used, censored = multi_interval_rate(stream, ticks // 2, 3)
    assert not censored.any() and np.all(used == n)
    sigma = np.sqrt(1 / (n * q - 1) + (0.5 * rate_per_tick / n) ** 2) / side
    rounding_bias = rate_per_tick / (2 * n)
    assert rate.mean() / rate_per_tick == pytest.approx(1.0, abs=5 * sigma + rounding_bias)
    if q == 1.0:
        assert abs(n * q / (n * q - 1) - 1) > 10 * sigma  # the test can tell the biased estimator apart
    adaptive, used_adaptive, _ = multi_interval_rate(stream, ticks // 2, 3, adaptive=True, tolerance=3.0)
    # at 3σ a steady pixel rarely stops early; the mean stays within the same tolerance
    assert np.mean(used_adaptive == n) > 0.9
    assert adaptive.mean() / rate_per_tick == pytest.approx(1.0, abs=5 * sigma * np.sqrt(n) + rounding_bias)


def test_adaptive_k_shrinks_where_the_light_steps():
    """Just before a ×4 step, fixed K mixes post-step intervals in; adaptive K keeps to the old light."""
    sensor = SpikeSensor(threshold_electrons=10_000.0, dark_current_e_per_s=0.0)
    clock = sensor.parameters.clock_hz
    rate_per_tick = 0.05
    lux = sensor.parameters.optics.lux_from_electrons_per_s(rate_per_tick * 10_000 * clock)
    step_tick = 400
    scene = StepScene(StillScene(np.full((16, 16), lux)), step_time_s=step_tick / clock, factor=4.0)
    stream = sensor.capture(scene, 800 / clock, seed=3)
    image_fixed = multi_interval_image(stream, (step_tick - 12 + 0.5) / clock, 4)
    image_adaptive = multi_interval_image(stream, (step_tick - 12 + 0.5) / clock, 4, adaptive=True)
    fixed = image_fixed.spikes_per_s.mean() / clock
    adaptive = image_adaptive.spikes_per_s.mean() / clock
    assert abs(adaptive / rate_per_tick - 1) < 0.1  # old light kept (the instant's interval is pre-step)
    assert fixed / rate_per_tick > 1.3  # fixed K reaches past the step
    assert image_adaptive.info["intervals"].mean() < image_fixed.info["intervals"].mean()


@pytest.mark.parametrize("group, margin", [(256, 256), (10, 3)])
def test_streamed_instants_equal_single_instants_whatever_the_grouping(group, margin):
    """Spike lists with a small margin force the far search; results equal the per-instant ones."""
    from viform.imaging.multi_interval import multi_interval_frames

    rng = np.random.default_rng(1)
    stream = SpikeStream(rng.random((1500, 4, 5)) < rng.uniform(0.0005, 0.5, (4, 5)), 1000.0)
    ticks = list(range(0, 1500, 47))
    for adaptive in (False, True):
        for k, rate, used, censored in multi_interval_frames(stream, ticks, 3, adaptive=adaptive, group_ticks=group,
                                                             margin_ticks=margin):
            expected = multi_interval_rate(stream, k, 3, adaptive=adaptive)
            assert np.array_equal(rate, expected[0]) and np.array_equal(used, expected[1])
            assert np.array_equal(censored, expected[2])


@pytest.mark.parametrize("q, mean_interval_ticks, instants, side", [
    (100.0, 1.2, 20, 24), (100.0, 1.5, 20, 24), (100.0, 2.5, 20, 24), (1000.0, 1.2, 20, 24), (100.0, 20.0, 8, 24),
    (100.0, 5000.0, 1, 24),
])
def test_rate_unbiased_after_tick_rounding_from_1_to_5000_ticks(q, mean_interval_ticks, instants, side):
    """Steady light whose firing rate is exactly r = 1/μ per tick (λ from the readout's rate law):
    the mean multi-interval rate (K = 4) is r within 5 standard errors of
    the mean over pixels × instants (instants a full span apart, so each pixel's estimates
    are independent; standard error std/√N). The old n / span read +0.69 % ± 0.02 % high at
    1.2 ticks (Q = 100), +0.43 % at 1.5, +1.1 % at Q = 1,000 and 1.2 ticks (module notes)."""
    from viform.imaging.rate_law import electrons_per_tick_from_rate

    k = 4
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    clock = sensor.parameters.clock_hz
    per_tick = float(electrons_per_tick_from_rate(1 / mean_interval_ticks, q)[0])
    lux = sensor.parameters.optics.lux_from_electrons_per_s(per_tick * clock)
    span = int(2 * k * mean_interval_ticks * 1.2) + 10
    stream = sensor.capture(StillScene(np.full((side, side), lux)), span * (instants + 1) / clock, seed=4)
    rates = np.concatenate([multi_interval_rate(stream, span // 2 + i * span, k)[0].ravel()
                            for i in range(instants)])
    se = rates.std() / np.sqrt(rates.size)
    assert abs(rates.mean() * mean_interval_ticks - 1) < 5 * se * mean_interval_ticks, rates.mean()
