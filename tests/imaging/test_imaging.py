"""Images at any instant (seed 000 §3.3): units, end rules, streaming, and motion sharpness."""

import numpy as np
import pytest

from viform.imaging import (
    accumulation_image,
    interval_frames,
    interval_image,
    interval_ticks,
    sliding_accumulation,
    tau_display_8bit,
)
from viform.light.scenes import StillScene, TranslatingScene
from viform.sensors.spike import SpikeSensor
from viform.stream.container import SpikeStream


def test_static_light_is_recovered_in_lux():
    """Accumulation over n spikes estimates lux within its Gamma-renewal standard error."""
    sensor = SpikeSensor(threshold_electrons=100, dark_current_e_per_s=20.0)
    lux = 2.0
    stream = sensor.capture(StillScene(np.full((32, 32), lux)), 0.05, seed=5)
    image = accumulation_image(stream, 0.0499, 0.04, align="end")
    spikes = image.spikes_per_s.mean() * 0.04
    # per-pixel counts have relative sd ≈ 1/√(n·Q); the mean over 1024 pixels 32× less
    rel = 1 / np.sqrt(spikes * 100) / 32
    assert image.lux.mean() == pytest.approx(lux, rel=5 * rel + 1e-3)
    itv = interval_image(stream, 0.025)
    assert not itv.censored.any()
    # The interval holding a fixed instant is length-biased, Gamma(Q + 1, λ), so E[Q/τ] = λ
    # exactly: no Q/(Q − 1) bias. Per pixel Q/τ has RSD 1/√(Q − 1) plus tick rounding
    # (1/6 tick² on a mean interval of μ ticks), whose Jensen bias is at most (1/6)/μ².
    mu = 100 / sensor.electrons_per_tick(lux)
    rsd = np.sqrt(1 / 99 + (1 / 6) / mu ** 2)
    assert itv.lux.mean() == pytest.approx(lux, rel=5 * rsd / 32 + (1 / 6) / mu ** 2)


def test_interval_end_rule_has_no_nan_and_flags_censoring():
    spikes = np.zeros((10, 1, 3), bool)
    spikes[4, 0, 0] = True  # one spike: both sides cut by the ends
    spikes[[2, 6], 0, 1] = True
    stream = SpikeStream(spikes, clock_hz=1000.0, threshold_electrons=10.0)
    tau, censored = interval_ticks(stream, [5])
    assert tau[0, 0].tolist() == [10 - 4, 6 - 2, 10 - (-1)]  # spike→end, full interval, none at all
    assert censored[0, 0].tolist() == [True, False, True]
    image = interval_image(stream, 0.0055)
    assert np.all(np.isfinite(image.spikes_per_s)) and np.all(image.spikes_per_s > 0)


def test_every_tick_stream_matches_single_instants_and_block_size():
    rng = np.random.default_rng(2)
    stream = SpikeStream(rng.random((120, 5, 6)) < 0.08, clock_hz=1000.0)
    a = np.concatenate([t for _, t in interval_frames(stream, block_ticks=7, lookahead_ticks=40)])
    b = np.concatenate([t for _, t in interval_frames(stream, block_ticks=120, lookahead_ticks=40)])
    assert np.array_equal(a, b)
    ticks = [0, 33, 119]
    tau, _ = interval_ticks(stream, ticks, lookahead_ticks=40)
    assert np.array_equal(a[ticks], tau)


def test_sliding_accumulation_equals_windowed_sums():
    rng = np.random.default_rng(3)
    spikes = rng.random((90, 3, 4)) < 0.3
    stream = SpikeStream(spikes, clock_hz=1000.0)
    counts = np.concatenate([c for _, c in sliding_accumulation(stream, 10, block_ticks=13)])
    cumulative = np.cumsum(spikes, axis=0)
    expected = cumulative.copy()
    expected[10:] -= cumulative[:-10]
    assert np.array_equal(counts, expected)


def test_seed_display_mapping_is_255_minus_normalised_tau():
    tau = np.array([[1, 128, 255]])
    assert tau_display_8bit(tau, percentiles=(0, 100)).tolist() == [[255, 128, 0]]
    # a single huge (dark) interval does not wash out the others with the default percentiles
    tau = np.concatenate([np.arange(1, 101), [10_000]])[None, :]
    shown = tau_display_8bit(tau)
    assert shown[0, 0] == 255 and shown[0, -1] == 0 and shown[0, 50] < 150


def test_moving_edge_interval_stays_sharp_where_long_accumulation_blurs():
    """A bright edge moving at 1000 px/s: the interval image tracks it; a 10 ms window smears 10 px.

    Both are scored against the analytic illuminance at the same instant: RMS error over the
    columns the edge swept during the accumulation window (50–62), and the 10–90 % edge width.
    """
    sensor = SpikeSensor(threshold_electrons=100, dark_current_e_per_s=0.0)
    scene = TranslatingScene(16, 96, velocity_px_per_s=(1000.0, 0.0), pattern="edge", min_lux=0.2, max_lux=2.0,
                             origin_px=(30.0, 0.0))
    stream = sensor.capture(scene, 0.04, seed=8)
    t = 0.0305  # edge at x = 60.5, between pixel centres; in the last 10 ms it swept 50.5 → 60.5
    truth = scene.illuminance_lux(t)
    band = slice(45, 75)
    swept = slice(50, 62)
    interval = interval_image(stream, t).lux
    accumulation = accumulation_image(stream, t, 0.010, align="end").lux
    err_interval = np.sqrt(np.mean((interval[:, swept] - truth[:, swept]) ** 2))
    err_accumulation = np.sqrt(np.mean((accumulation[:, swept] - truth[:, swept]) ** 2))
    assert err_interval < 0.5 * err_accumulation

    def edge_width_px(image):
        # rising edge: from the last column below 10 % to the first above 90 % of the step
        profile = image[:, band].mean(axis=0)
        lo, hi = np.median(profile[:5]), np.median(profile[-5:])
        last_low = np.flatnonzero(profile < lo + 0.1 * (hi - lo)).max()
        first_high = np.flatnonzero(profile > lo + 0.9 * (hi - lo)).min()
        return first_high - last_low

    assert edge_width_px(interval) <= 3
    assert edge_width_px(accumulation) >= 8


class _WideSource(SpikeStream):
    """A third-party source that hands out 0/1 as a wider dtype than the documented bool."""

    def __init__(self, spikes, dtype):
        super().__init__(spikes, 1000.0)
        self.dtype = dtype

    def read_ticks(self, start, stop):
        return super().read_ticks(start, stop).astype(self.dtype)


@pytest.mark.parametrize("dtype", [np.int64, np.float32, np.int8])
def test_a_source_of_wider_integers_gives_the_bool_results(dtype):
    """Compiled readers take one byte per pixel-tick: a source handing out int64 or float spikes is
    compared with 0 first, never read past its rows (it once wrote past the search's arrays)."""
    from viform.imaging.multi_interval import spike_ticks_around

    rng = np.random.default_rng(4)
    spikes = rng.random((300, 6, 10)) < rng.choice([0.0, 0.003, 0.05, 1.0], (6, 10))
    plain, wide = SpikeStream(spikes, 1000.0), _WideSource(spikes, dtype)
    for a, b in zip(interval_ticks(plain, [0, 150, 299], 7), interval_ticks(wide, [0, 150, 299], 7), strict=True):
        assert np.array_equal(a, b)
    for (_, a), (_, b) in zip(interval_frames(plain, 64, 5), interval_frames(wide, 64, 5), strict=True):
        assert np.array_equal(a, b)
    for (_, a), (_, b) in zip(sliding_accumulation(plain, 9, 50), sliding_accumulation(wide, 9, 50), strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(spike_ticks_around(plain, 150, 3, 3, 5), spike_ticks_around(wide, 150, 3, 3, 5), strict=True):
        assert np.array_equal(a, b)
