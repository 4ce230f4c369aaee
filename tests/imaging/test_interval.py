"""Interval imaging (seed 000 §3.3.2): exact at every interval length, in the API and the CLI.

The issue this guards: a fixed 1,024-tick lookahead cut every interval longer than ≈ 2,048
ticks, so dim light read too bright (+77 % at 0.005 lux) with every pixel flagged censored.
"""

import numpy as np
import pytest

from viform.cli import main
from viform.imaging import interval_frames, interval_image, interval_ticks
from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes

Q = 400.0  # e⁻: a realistic-order threshold keeps the per-pixel spread (1/√(Q − 1)) small
TAU_HAT_TICKS = 16_000  # longest signal interval Q / dark current, ticks
CLOCK_HZ = 40_000.0
DARK = Q / (TAU_HAT_TICKS / CLOCK_HZ)  # e⁻/s
# mean intervals from 2 ticks to τ̂/2 (where signal = dark current): far past the old 2,048 cut
TAUS_TICKS = np.array([2.0, 3.3, 7.0, 25.0, 120.0, 700.0, 2_500.0, 5_000.0, TAU_HAT_TICKS / 2])
ROWS = 24


def _reference_tau(spikes):
    """Brute-force τ at every tick: running max of previous spike, reversed running min of next."""
    n = spikes.shape[0]
    ticks = np.arange(n)[:, None, None]
    prev = np.maximum.accumulate(np.where(spikes, ticks, -1), axis=0)
    later = np.where(spikes, ticks, n)
    later = np.concatenate([later[1:], np.full((1,) + later.shape[1:], n)])
    nxt = np.minimum.accumulate(later[::-1], axis=0)[::-1]
    return nxt - prev


def test_every_length_is_exact_whatever_the_chunking():
    """Intervals from 1 tick to never: the streamed and single-instant results equal brute force."""
    rng = np.random.default_rng(0)
    p = np.array([0.5, 0.05, 0.003, 0.0005, 0.0])[None, None, :] * np.ones((1, 3, 1))
    spikes = rng.random((3000, 3, 5)) < p
    stream = SpikeStream(spikes, 1000.0)
    expected = _reference_tau(spikes)
    for block, look in [(7, 3), (1000, 1), (3000, 3000), (13, 500)]:
        got = np.concatenate([t for _, t in interval_frames(stream, block_ticks=block, lookahead_ticks=look)])
        assert np.array_equal(got, expected), (block, look)
    ticks = [0, 1, 500, 1499, 2999]
    for look in (1, 5, None):
        tau, censored = interval_ticks(stream, ticks, look)
        assert np.array_equal(tau, expected[ticks])
        # censored only where the interval reaches an end of the stream
        never = ~spikes.any(axis=0)
        assert np.all(censored[:, never]) and not censored[2, 0, 0]


@pytest.mark.parametrize("shape", [(70, 80), (33, 37)], ids=["whole-words", "partial-word"])
def test_search_exact_across_slabs_words_and_a_subset(shape):
    """The compiled search (8 pixels a word, 4,096 a slab, a list of words still to find) against
    brute force: several slabs, a last partial word, pixels that fire every tick or never, spikes
    as any nonzero byte, and only the listed pixels touched."""
    from viform.imaging.interval import _collect_spikes

    rng = np.random.default_rng(3)
    n, pixels = 400, shape[0] * shape[1]
    rate = rng.choice([0.0, 1e-3, 0.01, 0.2, 1.0], size=pixels)
    spikes = rng.random((n, pixels)) < rate
    ticks = np.arange(n)[:, None]
    first = np.where(spikes.any(axis=0), np.where(spikes, ticks, n).min(axis=0), -5)
    last = np.where(spikes.any(axis=0), np.where(spikes, ticks, -1).max(axis=0), -5)
    todo0 = rng.random(pixels) < 0.7
    # a spike is any nonzero byte (a bool array can hold 2…255)
    spike_bytes = (spikes * rng.integers(1, 256, spikes.shape)).astype(np.uint8)
    for backward, expected in ((False, first), (True, last)):
        todo, out = todo0.copy(), np.full(pixels, -5, np.int64)
        _collect_spikes(spike_bytes, 1000, backward, todo, out[None], np.zeros(pixels, np.int64), 1)
        want = np.where(todo0 & (expected >= 0), expected + 1000, -5)
        assert np.array_equal(out, want), backward
        assert np.array_equal(todo, todo0 & (expected < 0))
    stream = SpikeStream(spikes.reshape(n, *shape), 1000.0)
    reference = _reference_tau(stream.spikes)
    for look in (1, 37, None):
        tau, _ = interval_ticks(stream, [0, 199, 399], look)
        assert np.array_equal(tau, reference[[0, 199, 399]]), look


@pytest.fixture(scope="module")
def flat_stream():
    """Columns of flat light, one mean interval each, 24 independent pixels per column."""
    sensor = SpikeSensor(threshold_electrons=Q, dark_current_e_per_s=DARK, clock_hz=CLOCK_HZ)
    optics = sensor.parameters.optics
    lux = optics.lux_from_electrons_per_s(Q / TAUS_TICKS * CLOCK_HZ - DARK)
    scene = StillScene(np.tile(lux, (ROWS, 1)))
    # 3 τ̂/2 either side of the middle instant: the interval holding it is never cut by an end
    duration_s = 3 * TAU_HAT_TICKS / CLOCK_HZ
    return sensor, lux, sensor.capture(scene, duration_s, seed=11)


def _tolerance(mu_ticks, lux):
    """5σ of a column mean of Q/τ (relative), in lux after the dark current is removed.

    The interval holding an instant is Gamma(Q + 1) in electrons, so Q/τ is unbiased with
    relative sd 1/√(Q − 1); tick rounding moves τ by under one tick (sd ≤ ½ tick on τ ≥ μ − 1)
    and, the interval being picked ∝ its length in ticks too, adds no bias. The dark current
    is subtracted, so the relative error in lux is larger by (signal + dark) / signal.
    """
    rsd = np.sqrt(1 / (Q - 1) + 0.25 / np.maximum(mu_ticks - 1, 1) ** 2)
    return 5 * rsd / np.sqrt(ROWS) * (Q / mu_ticks * CLOCK_HZ) / (Q / mu_ticks * CLOCK_HZ - DARK)


def test_flat_light_unbiased_from_2_ticks_to_half_tau_hat_with_defaults(flat_stream):
    _, lux, stream = flat_stream
    image = interval_image(stream, stream.duration_s / 2)  # default options
    assert not image.censored.any()
    got = image.lux.mean(axis=0)
    assert np.all(np.abs(got / lux - 1) < _tolerance(TAUS_TICKS, lux)), got / lux


def test_flat_light_unbiased_through_the_cli(flat_stream, tmp_path, capsys):
    sensor, lux, stream = flat_stream
    path = save_spikes(tmp_path / "flat.zarr", stream)  # keeps Q, clock and optics
    out = tmp_path / "img"
    code = main(["reconstruct", str(path), "--method", "interval", "--at", str(stream.duration_s / 2),
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    light = np.load(out / "light.npz")
    assert not light["censored"].any()
    got = light["lux"][0].mean(axis=0)
    assert np.all(np.abs(got / lux - 1) < _tolerance(TAUS_TICKS, lux)), got / lux
