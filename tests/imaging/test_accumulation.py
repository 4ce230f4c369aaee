"""Accumulation window alignment: centred (published TFP convention, default), end (causal), start."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.imaging import accumulation_8bit, accumulation_image
from viform.imaging.accumulation import window_bounds
from viform.stream.container import SpikeStream


def test_window_bounds_for_each_alignment_and_at_the_ends():
    assert window_bounds(150, 41, 301, "centre") == (130, 171)  # the instant ± 20: the 41-tick TFP
    assert window_bounds(150, 41, 301, "center") == (130, 171)
    assert window_bounds(150, 41, 301, "end") == (110, 151)
    assert window_bounds(150, 41, 301, "start") == (150, 191)
    assert window_bounds(5, 41, 301, "centre") == (0, 26)  # clipped at the start
    assert window_bounds(295, 41, 301, "start") == (295, 301)
    with pytest.raises(ViformError, match="align = 'middle'"):
        window_bounds(5, 41, 301, "middle")


def test_default_is_centred_and_matches_the_8bit_tfp():
    rng = np.random.default_rng(4)
    spikes = rng.random((301, 6, 5)) < 0.3
    stream = SpikeStream(spikes, clock_hz=40_000.0)
    t = (150 + 0.5) / 40_000
    window_s = 41 / 40_000
    centred = accumulation_image(stream, t, window_s)
    per_tick = centred.spikes_per_s / 40_000
    assert np.allclose(per_tick, spikes[130:171].mean(axis=0))
    assert np.array_equal(np.clip(np.rint(per_tick * 255 / 0.6), 0, 255).astype(np.uint8),
                          accumulation_8bit(stream, 150, 20, 0.6))
    ended = accumulation_image(stream, t, window_s, align="end").spikes_per_s / 40_000
    assert np.allclose(ended, spikes[110:151].mean(axis=0))
    started = accumulation_image(stream, t, window_s, align="start").spikes_per_s / 40_000
    assert np.allclose(started, spikes[150:191].mean(axis=0))
    assert centred.info["align"] == "centre" and centred.info["first_tick"] == 130
