"""Spike sensor (seed 000 §3.2, §5.1): Gamma intervals, dark firing, saturation, reproducibility.

Tolerances come from the statistics: with n independent intervals the sample mean has
standard error σ/√n and the sample standard deviation a relative standard error of
√((2 + κ)/(4n)), κ = 6/Q the Gamma excess kurtosis. Intervals are measured in whole ticks,
which adds a variance of 1/6 tick² (two uniform rounding errors); the tests keep the mean
interval long (≥ 200 ticks) so that term is small, and include it anyway.
"""

import math

import numpy as np
import pytest
from scipy import stats

from viform._validate import ViformError
from viform.light.scenes import StillScene, builtin_scene
from viform.sensors._gamma import gamma_samples
from viform.sensors.spike import CHIP_THRESHOLD_LEVELS_ELECTRONS, SpikeSensor


def lux_for_electrons_per_tick(sensor, electrons_per_tick):
    p = sensor.parameters
    signal = electrons_per_tick * p.clock_hz - p.dark_current_e_per_s
    return signal / p.optics.electrons_per_lux_second


def intervals_in_ticks(spikes):
    flat = spikes.reshape(spikes.shape[0], -1)
    out = []
    for p in range(flat.shape[1]):
        out.append(np.diff(np.flatnonzero(flat[:, p])))
    return np.concatenate(out)


@pytest.mark.parametrize("q", [100, 1000])
def test_interval_mean_and_rsd_follow_gamma(q):
    """Seed 000 §5.1: mean interval Q/λ, RSD 1/√Q (10 % at Q = 100, 3.16 % at Q = 1000)."""
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    mean_ticks = 250.0
    lux = lux_for_electrons_per_tick(sensor, q / mean_ticks)
    stream = sensor.capture(StillScene(np.full((16, 16), lux)), 1.0, seed=11)
    isi = intervals_in_ticks(stream.spikes)
    n = isi.size
    assert n > 30_000
    sd_expected = math.sqrt(mean_ticks ** 2 / q + 1 / 6)
    assert abs(isi.mean() - mean_ticks) < 5 * sd_expected / math.sqrt(n)
    rsd = isi.std(ddof=1) / isi.mean()
    rsd_expected = sd_expected / mean_ticks
    assert rsd_expected == pytest.approx(1 / math.sqrt(q), rel=0.01)
    assert abs(rsd / rsd_expected - 1) < 5 * math.sqrt((2 + 6 / q) / (4 * n))


@pytest.mark.parametrize("shape", [1.0, 7.0, 100.0, 1000.0])
def test_gamma_sampler_is_exact(shape):
    """The table sampler passes a Kolmogorov–Smirnov test against Gamma(a, 1) on 2e5 draws."""
    x = gamma_samples(shape, 200_000, key=12345)
    assert stats.kstest(x, stats.gamma(shape).cdf).pvalue > 1e-3
    assert x.mean() == pytest.approx(shape, abs=5 * math.sqrt(shape / x.size))


def test_dark_only_pixels_fire_at_dark_current_over_q():
    """Seed 000 §4.4: with no light a pixel fires at Id/Q (τ̂ = Q/Id)."""
    q, dark = 20, 2000.0
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=dark)
    duration = 2.0
    stream = sensor.capture(StillScene(np.zeros((16, 16))), duration, seed=3, light_sample_ticks=80_000)
    rate = stream.spike_count() / (16 * 16 * duration)
    expected = dark / q
    # renewal counting: variance ≈ rate·T/Q per pixel
    se = math.sqrt(expected * duration / q / (16 * 16)) / duration
    assert abs(rate - expected) < 5 * se + 1.0 / duration
    assert sensor.parameters.longest_signal_interval_s == pytest.approx(q / dark)


def test_saturation_at_one_spike_per_tick():
    """Light above Q·clock fires every tick and no more: the one-bit readout caps the rate."""
    sensor = SpikeSensor(threshold_electrons=100)
    lux = lux_for_electrons_per_tick(sensor, 10 * 100)
    stream = sensor.capture(StillScene(np.full((8, 8), lux)), 0.01, seed=1)
    assert stream.spikes.all()


@pytest.mark.parametrize("per_tick,self_rate,readout_rate", [(0.25, 0.25, 0.25), (0.6, 0.6, 0.5), (1.5, 1.0, 1.0)])
def test_noise_free_firing_and_reset_variants(per_tick, self_rate, readout_rate):
    """Deterministic model: self-reset fires at min(λdt/Q, 1); reset-at-readout at 1/ceil(Q/λdt)."""
    q = 100
    for reset, expected in (("self", self_rate), ("readout", readout_rate)):
        sensor = SpikeSensor(threshold_electrons=q, photon_noise=False, dark_current_e_per_s=0.0, reset=reset,
                             random_initial_charge=False)
        lux = lux_for_electrons_per_tick(sensor, per_tick * q)
        stream = sensor.capture(StillScene(np.full((2, 2), lux)), 0.05, seed=0)
        assert stream.spikes.mean() == pytest.approx(expected, abs=2 / stream.n_ticks)


def test_same_seed_same_bits_whatever_the_block_size():
    sensor = SpikeSensor(threshold_spread_fraction=0.05)
    scene = builtin_scene("translating", 24, 40)
    a = sensor.capture(scene, 0.02, seed=9, block_ticks=800).spikes
    b = sensor.capture(scene, 0.02, seed=9, block_ticks=37).spikes
    c = sensor.capture(scene, 0.02, seed=10, block_ticks=800).spikes
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_same_bits_whatever_the_number_of_threads():
    from numba import get_num_threads, set_num_threads

    sensor = SpikeSensor()
    scene = builtin_scene("translating", 24, 40)
    before = get_num_threads()
    try:
        set_num_threads(1)
        a = sensor.capture(scene, 0.01, seed=4).spikes
        set_num_threads(before)
        b = sensor.capture(scene, 0.01, seed=4).spikes
    finally:
        set_num_threads(before)
    assert np.array_equal(a, b)


def test_threshold_spread_is_fixed_pattern():
    sensor = SpikeSensor(threshold_spread_fraction=0.1)
    q = sensor.threshold_map_electrons(64, 64)
    assert q.std() / q.mean() == pytest.approx(0.1, rel=0.1)
    assert np.array_equal(q, SpikeSensor(threshold_spread_fraction=0.1).threshold_map_electrons(64, 64))


def test_chip_threshold_levels():
    assert len(CHIP_THRESHOLD_LEVELS_ELECTRONS) == 16
    assert 100 in CHIP_THRESHOLD_LEVELS_ELECTRONS
    assert np.all(np.diff(CHIP_THRESHOLD_LEVELS_ELECTRONS) > 0)


def test_lazy_stream_equals_capture():
    sensor = SpikeSensor()
    scene = builtin_scene("rotating", 16, 24)
    lazy = sensor.stream(scene, 0.005, seed=2)
    full = sensor.capture(scene, 0.005, seed=2)
    assert np.array_equal(lazy.read_ticks(30, 90), full.spikes[30:90])


@pytest.mark.parametrize("field,value", [("threshold_electrons", 0), ("threshold_electrons", -5),
                                         ("clock_hz", 0), ("clock_hz", -1.0), ("reset", "never")])
def test_bad_parameters_name_themselves(field, value):
    with pytest.raises(ViformError, match=field):
        SpikeSensor(**{field: value})


@pytest.mark.parametrize("reset", ["self", "readout"])
def test_vectorized_noise_free_kernel_matches_the_event_kernel(reset):
    """The noise-free model runs a SIMD tick loop; it must give the event-driven kernel's bits."""
    from viform.sensors import spike as module

    sensor = SpikeSensor(photon_noise=False, reset=reset)
    scene = builtin_scene("hdr", 20, 50)  # includes pixels above the one-spike-per-tick limit
    vectorized = sensor.capture(scene, 0.01, seed=3).spikes
    q, _, index, tables = sensor._pixel_tables(20, 50)
    state = sensor.initial_state(20, 50, 3)
    blocks = []
    for first, last in ((0, 123), (123, 400)):
        out = np.empty((last - first, 1000), dtype=bool)
        lux = scene.illuminance_lux_many((np.arange(first, last) + 0.5) / sensor.parameters.clock_hz)
        rates = np.rint(sensor.electrons_per_tick(lux.reshape(last - first, -1)) * module.FIXED_POINT_SCALE)
        module._run_block(out, rates.astype(np.int64), first, 1, first, state.charge, state.target, state.counter,
                          q, index, *tables, state.keys, False, reset == "readout")
        blocks.append(out.reshape(-1, 20, 50))
    assert np.array_equal(vectorized, np.concatenate(blocks))
    assert 0.05 < vectorized.mean() < 1.0


def test_reused_block_buffer_gives_the_same_bits():
    """With ``reuse_buffer`` blocks share one buffer; consumed at once they equal fresh blocks."""
    sensor = SpikeSensor()
    scene = builtin_scene("translating", 12, 20)
    fresh = np.concatenate([b for _, b in sensor.simulate(scene, 0.005, seed=6, block_ticks=33)])
    reused = np.concatenate([b.copy() for _, b in sensor.simulate(scene, 0.005, seed=6, block_ticks=33,
                                                                   reuse_buffer=True)])
    assert np.array_equal(fresh, reused)
    lazy = sensor.stream(scene, 0.005, seed=6, reuse_buffer=True)
    assert np.array_equal(lazy.read_ticks(10, 150), fresh[10:150])  # read_ticks never shares
