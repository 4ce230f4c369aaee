"""The per-pixel interval predictor of strict .vfc version 3: exact round trips and what it saves."""

import numpy as np
import pytest

from viform.coding import interval_model as im
from viform.coding.first_spike import CodingParameters, FirstSpikeDecoder, encode_array


def _beatty(mu, n_ticks, n_pix, rsd=0.0, seed=0):
    """Integrate-and-fire spike trains: crossings every mu ticks (relative jitter rsd), read at whole ticks."""
    rng = np.random.default_rng(seed)
    out = np.zeros((n_ticks, n_pix), bool)
    for p in range(n_pix):
        x = rng.random() * mu[p]
        while x < n_ticks:
            out[int(x), p] = True
            x += mu[p] * (1 + rsd * rng.standard_normal())
    return out


def _code(spikes, width, segment_ticks):
    """Code every segment with the interval model, then decode it back; returns (bytes, decoded ticks ok)."""
    t, n_pix = spikes.shape
    segs = encode_array(spikes, CodingParameters(segment_ticks=segment_ticks))
    enc_state = FirstSpikeDecoder(n_pix)
    st_e, pr_e = np.zeros((n_pix, im.STATE_ROWS), np.int64), im.new_probabilities()
    st_d, pr_d = np.zeros((n_pix, im.STATE_ROWS), np.int64), im.new_probabilities()
    total = 0
    for seg in segs:
        ticks = np.empty(seg.n_spikes + 1, np.int64)
        counts = np.empty(n_pix, np.int64)
        im.ticks_from_records(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, enc_state.anchor,
                              enc_state.tau_ref, seg.start_tick, counts, ticks)
        out = np.empty(4 * seg.n_spikes + n_pix + 4096, np.uint8)
        end = seg.start_tick + seg.n_ticks
        n = im.encode_segment(counts, ticks, enc_state.anchor, st_e, pr_e, seg.start_tick, end, width, out, 3)
        assert n <= out.size
        total += n
        got_counts = np.empty(n_pix, np.int64)
        got = np.empty(seg.n_spikes + 1, np.int64)
        # read-only bytes, as the readers pass them (the same compiled specialisation)
        data = np.frombuffer(out[:n].tobytes(), np.uint8)
        err, n_sp = im.decode_segment(data, n_pix, enc_state.anchor, st_d, pr_d, seg.start_tick, end, width,
                                      seg.n_spikes, got_counts, got, 3)
        assert err == 0 and n_sp == seg.n_spikes
        assert np.array_equal(got_counts, counts) and np.array_equal(got[:n_sp], ticks[:n_sp])
        # spike ticks back to the first-spike records (the strict rule) give the same records
        rc = np.empty(n_pix, np.int64)
        m, g, o = (np.empty(max(1, seg.n_spikes), np.int64) for _ in range(3))
        tm, tg = np.empty(n_pix, np.int64), np.empty(n_pix, np.int64)
        nr = im.records_from_ticks(got_counts, got, enc_state.anchor, enc_state.tau_ref, rc, m, g, o, tm, tg)
        assert nr == seg.m.size and np.array_equal(rc, seg.counts) and np.array_equal(o[:nr], seg.o)
        assert np.array_equal(m[:nr], seg.m) and np.array_equal(tm, seg.tail_m) and np.array_equal(tg, seg.tail_g)
        enc_state.check(seg, advance=True)
    assert np.array_equal(st_e, st_d) and np.array_equal(pr_e, pr_d)  # carried state agrees
    return total


@pytest.mark.parametrize("segment_ticks", [5, 37, 400])
def test_round_trip_across_segments(segment_ticks):
    """Random, regular, dark and late-waking pixels, cut into segments of several lengths: exact."""
    rng = np.random.default_rng(1)
    n_pix = 48
    mu = rng.uniform(1.0, 30.0, n_pix)
    spikes = _beatty(mu, 400, n_pix, rsd=0.05, seed=2)
    spikes[:, :6] = rng.random((400, 6)) < 0.4  # noisy pixels
    spikes[:, 6] = False  # never fires
    spikes[:250, 7:9] = False  # wake up late
    spikes[150:, 9] = False  # go dark
    spikes[::3, 10] = True  # spikes every third tick
    _code(spikes, 8, segment_ticks)


def test_regular_pixels_cost_a_fraction_of_a_bit():
    """Noise-free steady light (intervals ⌊μ⌋/⌈μ⌉ in a fixed pattern): the phase-locked prediction
    codes a spike in under half the order-0 entropy of the pixel's own intervals (what a model of
    the interval values alone, knowing each pixel's two values and their frequencies, would need)."""
    n_pix = 64
    mu = np.linspace(2.3, 19.7, n_pix)
    spikes = _beatty(mu, 3000, n_pix)
    n_bytes = _code(spikes, 8, 4096)
    h0 = 0.0
    for p in range(n_pix):
        _, c = np.unique(np.diff(np.flatnonzero(spikes[:, p])), return_counts=True)
        h0 -= (c * np.log2(c / c.sum())).sum()
    assert 8 * n_bytes < 0.5 * h0
