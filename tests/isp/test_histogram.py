"""Histogram counter and equalization (seed 002 §3.2.2-§3.2.3, eqs. (2)-(4))."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.isp.histogram import (
    StreamEqualizer,
    equalization_lut_float,
    equalization_lut_shift,
    equalize,
    histogram_counter,
    seed_shift_terms,
    shift_error,
    shift_map,
    to_gray8,
)

N_SEED = 1280 * 720


def _frame(seed=0, shape=(720, 1280)):
    rng = np.random.default_rng(seed)
    # A dark, low-contrast frame (what equalization is for) with runs of equal pixels.
    g = np.clip(rng.normal(40, 12, shape), 0, 255).astype(np.uint8)
    g[:, :64] = 250
    return g


def test_counter_equals_bincount_and_fits_20_bits():
    """8 banks × 256 twenty-bit counters (2 048 counters), summed after the frame."""
    g = _frame()
    hist, lanes = histogram_counter(g, return_lanes=True)
    assert lanes.shape == (8, 256)
    np.testing.assert_array_equal(hist, np.bincount(g.ravel(), minlength=256))
    assert hist.sum() == N_SEED < 2 ** 20
    # Each bank sees every 8th pixel: with 8 equal neighbours each bank counts one of them.
    np.testing.assert_array_equal(lanes[:, 250], np.full(8, 720 * 64 // 8))


def test_counter_overflow_is_refused():
    """A full 1280 × 864 frame (1 105 920 pixels) can overflow a 20-bit bin."""
    with pytest.raises(ViformError, match="counter_bits"):
        histogram_counter(np.zeros((864, 1280), dtype=np.uint8))
    assert histogram_counter(np.zeros((864, 1280), dtype=np.uint8), counter_bits=21)[0] == 864 * 1280


def test_seed_shift_terms_for_921600_pixels():
    """×255 as << 8 and ÷921 600 as >> 20 → c >> 12; error 0.000 03·c → + c >> 15."""
    assert seed_shift_terms(N_SEED) == (12, 15, 1)
    e = shift_error(N_SEED)
    # Seed eq. (4): the uncompensated error grows as 0.000 03 · c.
    assert e["error_slope_per_count"] == pytest.approx(3e-5, rel=0.1)
    assert e["error_at_full_uncompensated"] == 255 - (N_SEED >> 12)   # 30 levels
    # Compensation cuts the worst error about 8×; what remains is the 2.03e-6·c residual
    # slope (1.9 levels at c = N) plus the truncation of two shifts (< 2 levels).
    assert e["max_abs_error_compensated"] < 4.0 < e["max_abs_error_uncompensated"] / 7
    c = np.arange(0, N_SEED + 1, 997, dtype=np.int64)
    np.testing.assert_array_equal(shift_map(c, N_SEED, compensate=True), (c >> 12) + (c >> 15))


def test_shift_lut_close_to_float_lut():
    g = _frame(1)
    hist = histogram_counter(g)
    lf = equalization_lut_float(hist)
    assert lf[-1] == pytest.approx(255)
    assert np.all(np.diff(lf) >= 0)
    ls = equalization_lut_shift(hist).astype(float)
    lu = equalization_lut_shift(hist, compensate=False).astype(float)
    assert np.max(np.abs(ls - lf)) < 4.0
    assert np.max(np.abs(lu - lf)) > 20
    # Equalization spreads a dark, narrow histogram over the range.
    out = equalize(g, ls)
    assert out[:, 64:].std() > 3 * g[:, 64:].std()


def test_stream_previous_vs_same_frame():
    frames = [_frame(s, (90, 160)) for s in range(3)]
    prev = StreamEqualizer("previous")
    same = StreamEqualizer("same")
    out_prev = [prev(f) for f in frames]
    out_same = [same(f) for f in frames]
    np.testing.assert_array_equal(out_prev[0], frames[0])             # no histogram yet
    lut0 = equalization_lut_shift(histogram_counter(frames[0]))
    np.testing.assert_array_equal(out_prev[1], lut0[frames[1]])       # previous frame's LUT
    lut2 = equalization_lut_shift(histogram_counter(frames[2]))
    np.testing.assert_array_equal(out_same[2], lut2[frames[2]])
    fl = StreamEqualizer("same", method="float")(frames[2])
    assert np.max(np.abs(fl.astype(int) - out_same[2].astype(int))) <= 4


def test_to_gray8_keeps_high_bits_and_bad_inputs():
    assert to_gray8(np.array([1023, 4, 3]), 10).tolist() == [255, 1, 0]
    with pytest.raises(ViformError, match="gray"):
        histogram_counter(np.array([300, 2]))
    with pytest.raises(ViformError, match="empty"):
        equalization_lut_float(np.zeros(256))
    with pytest.raises(ViformError, match="source"):
        StreamEqualizer("next")
