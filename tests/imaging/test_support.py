"""The shared sparse-stream check (viform.imaging.support): figures, threshold and message."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from viform._validate import ViformError
from viform.imaging.support import MIN_SHARE, imaging_need, spike_support, support_from_rates
from viform.stream.container import SpikeStream


def _bernoulli(p_left, p_right, ticks=2000, shape=(20, 30), seed=0):
    """Left half fires p_left per tick, right half p_right (independent Bernoulli ticks)."""
    rng = np.random.default_rng(seed)
    p = np.where(np.arange(shape[1]) < shape[1] // 2, p_left, p_right)
    return SpikeStream(rng.random((ticks, *shape)) < p, 40e3, 100.0)


def test_dense_stream_is_enough_and_says_nothing():
    support = spike_support(_bernoulli(0.3, 0.3), 40, 2)
    assert support.firing_per_pixel_tick == pytest.approx(0.3, rel=0.02)  # 1.2M Bernoulli draws: σ ≈ 0.15 %
    assert support.typical_spikes == pytest.approx(12, rel=0.05)
    assert support.enough and support.share_enough == 1.0
    assert support.warning("flow", "more light") is None


def test_sparse_stream_warns_in_one_line_with_the_figures():
    support = spike_support(_bernoulli(0.0009, 0.0009, ticks=4000), 40, 2)
    assert not support.enough and support.share_enough == 0.0
    message = support.warning("flow over --dt 0.001 s", "brighten the scene")
    assert message.startswith("warning:") and "\n" not in message
    assert "0.0009" in message and "spikes per pixel-tick" in message and "brighten the scene" in message
    assert "2 are needed" in message and "40-tick window" in message


def test_share_follows_the_pixels_that_get_their_spikes():
    # half the pixels fire 0.3 per tick (12 spikes per 40 ticks expected), half 0.01 (0.4): with a need of
    # 2, half get them — the share sits at the threshold and decides "enough"
    support = spike_support(_bernoulli(0.3, 0.01), 40, 2)
    assert support.share_enough == pytest.approx(0.5)
    assert support.enough == (0.5 >= MIN_SHARE)
    # the rates' own rule: expected count rate·window against the need
    rates = np.array([0.0, 0.04, 0.05, 0.06, 1.0])
    s = support_from_rates(rates, 40, 2)
    assert s.share_enough == pytest.approx(3 / 5)  # 0.05·40 = 2 counts as enough
    assert s.typical_spikes == pytest.approx(2.0)


def test_share_matches_the_binomial_law():
    # each pixel fires Bernoulli(0.1) on 1,000 ticks: with a window of 20 ticks and a need of 2 it counts
    # as enough when its count reaches 100, which happens with probability P(Binomial(1000, 0.1) ≥ 100);
    # over 600 independent pixels the share has sd √(P(1 − P)/600) ≈ 0.02: 4 sd allowed
    stream = _bernoulli(0.1, 0.1, ticks=1000, seed=3)
    support = spike_support(stream, 20, 2)
    expected = binom.sf(99, 1000, 0.1)
    sd = np.sqrt(expected * (1 - expected) / 600)
    assert abs(support.share_enough - expected) < 4 * sd
    assert support.sampled_ticks == 1000


def test_needs_of_each_imaging_method():
    assert imaging_need("accumulation", 1000, 41) == (41, 4.0)
    assert imaging_need("interval", 1000) == (1000, 2.0)
    assert imaging_need("multi-interval", 1000, spikes_per_side=3) == (1000, 6.0)
    assert imaging_need("motion", 500) == (500, 8.0)
    with pytest.raises(ViformError, match="method = 'tfp'"):
        imaging_need("tfp", 100)
    with pytest.raises(ViformError, match="start_tick"):
        spike_support(_bernoulli(0.1, 0.1, ticks=10), 5, 2, start_tick=20, stop_tick=30)
    with pytest.raises(ViformError, match="window_ticks"):
        support_from_rates([0.1], 0, 2)
