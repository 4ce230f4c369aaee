"""The spike kernels give the same bits as before issue 30 (golden hashes) for every scene kind and option.

The hashes below were computed with the kernels of commit 866098e (before the lane/packed-bit
rewrite) by running this file as a script (``python tests/sensors/test_spike_kernel.py``);
the rewrite must reproduce them bit for bit: the spikes of every tick and the pixels' final
state (charge, target, draw counter). Cases avoid the two things another change owns (the
threshold-spread law, the initial state with dead time): thresholds that vary per pixel come
from a map given here, and dead-time cases start from the state of the same sensor without
dead time, so the kernel alone is compared.
"""

from __future__ import annotations

import hashlib
import sys

import numpy as np
import pytest

from viform.light.scenes import (
    FlickerScene,
    HDRScene,
    RotatingScene,
    StepScene,
    StillScene,
    TranslatingScene,
    VideoScene,
)
from viform.sensors.spike import SpikeSensor

E_PER_LUX_TICK = 286347.6261332859 / 40e3  # electrons per lux per 40 kHz tick of the default pixel


class _MapSensor(SpikeSensor):
    """A sensor whose per-pixel thresholds are a fixed map (not the spread law under change elsewhere)."""

    def threshold_map_electrons(self, height, width):
        levels = np.array([1.0, 3.0, 40.0, 100.0, 2500.0])
        return levels[(np.arange(height * width) * 7 + 3) % levels.size].reshape(height, width)


def _texture(height, width, lo_lux, hi_lux, seed=3):
    rng = np.random.default_rng(seed)
    return lo_lux * (hi_lux / lo_lux) ** rng.random((height, width))


def _video(height, width, n, seed=4):
    rng = np.random.default_rng(seed)
    return 0.2 + 4.0 * rng.random((n, height, width))


# name: (sensor factory, scene factory, ticks, simulate options, start from the no-dead-time twin's state)
CASES = {
    "still-exact": (lambda: SpikeSensor(), lambda: StillScene(_texture(12, 40, 0.01, 10.0)), 300, {}, False),
    "still-exact-empty-start": (lambda: SpikeSensor(random_initial_charge=False),
                                lambda: StillScene(_texture(11, 27, 0.5, 30.0)), 300, {}, False),
    "hdr-q1": (lambda: SpikeSensor(threshold_electrons=1), lambda: HDRScene(8, 64, 0.001, 8.0), 200, {}, False),
    "hdr-q7": (lambda: SpikeSensor(threshold_electrons=7), lambda: HDRScene(8, 64, 0.001, 8.0), 200, {}, False),
    "hdr-q100": (lambda: SpikeSensor(), lambda: HDRScene(8, 64, 0.01, 7.0), 200, {}, False),
    "hdr-q2e4": (lambda: SpikeSensor(threshold_electrons=2e4), lambda: HDRScene(6, 48, 1.0, 6.0), 200, {}, False),
    "hdr-readout": (lambda: SpikeSensor(reset="readout"), lambda: HDRScene(6, 40, 0.01, 7.0), 200, {}, False),
    "still-noise-free": (lambda: SpikeSensor(photon_noise=False), lambda: StillScene(_texture(12, 40, 0.01, 900.0)),
                         300, {}, False),
    "still-noise-free-readout": (lambda: SpikeSensor(photon_noise=False, reset="readout"),
                                 lambda: StillScene(_texture(11, 27, 0.01, 300.0)), 300, {}, False),
    "still-noise-free-empty": (lambda: SpikeSensor(photon_noise=False, random_initial_charge=False),
                               lambda: StillScene(_texture(12, 40, 0.1, 10.0)), 300, {}, False),
    "fixed-patterns": (lambda: SpikeSensor(gain_spread_fraction=0.2, dark_current_spread_fraction=1.0,
                                           hot_pixel_fraction=0.1, hot_pixel_dark_current_e_per_s=3e5),
                       lambda: StillScene(_texture(12, 40, 0.001, 3.0)), 300, {}, False),
    "threshold-map": (lambda: _MapSensor(), lambda: StillScene(_texture(12, 40, 0.01, 3e4)), 300, {}, False),
    "threshold-map-translating": (lambda: _MapSensor(), lambda: TranslatingScene(12, 40, (900.0, 300.0),
                                                                                   min_lux=0.1, max_lux=3e3),
                                  300, {}, False),
    "step": (lambda: SpikeSensor(), lambda: StepScene(StillScene(_texture(12, 40, 0.1, 10.0)), 0.004, 30.0),
             300, {}, False),
    "video-hold": (lambda: SpikeSensor(), lambda: VideoScene(_video(12, 40, 6), 2000.0, "hold"), 300, {}, False),
    "video-linear": (lambda: SpikeSensor(), lambda: VideoScene(_video(12, 40, 6), 2000.0, "linear"), 300, {},
                     False),
    "video-linear-odd": (lambda: SpikeSensor(threshold_electrons=30),
                         lambda: VideoScene(_video(11, 27, 5), 2500.0, "linear"), 300, {}, False),
    "translating": (lambda: SpikeSensor(), lambda: TranslatingScene(12, 40, (2000.0, 500.0)), 300, {}, False),
    "translating-noise-free": (lambda: SpikeSensor(photon_noise=False),
                               lambda: TranslatingScene(12, 40, (2000.0, 500.0)), 300, {}, False),
    # the next two recorded with the kernels of 1d1c8f7, before the per-tick kernel took the noise-free
    # models in line (a moving scene with readout reset; one with many crossings a tick)
    "translating-noise-free-readout": (lambda: SpikeSensor(photon_noise=False, reset="readout"),
                                       lambda: TranslatingScene(12, 40, (2000.0, 500.0)), 300, {}, False),
    "moving-edge-noise-free": (lambda: SpikeSensor(photon_noise=False),
                               lambda: TranslatingScene(12, 40, (3000.0, 0.0), pattern="edge", min_lux=0.5,
                                                        max_lux=2e4), 300, {}, False),
    "moving-edge": (lambda: SpikeSensor(), lambda: TranslatingScene(12, 40, (3000.0, 0.0), pattern="edge",
                                                                      min_lux=0.5, max_lux=2e4), 300, {}, False),
    "bars-readout": (lambda: SpikeSensor(reset="readout"), lambda: TranslatingScene(12, 40, (1000.0, 0.0),
                                                                                     pattern="bars"), 300, {}, False),
    "rotating": (lambda: SpikeSensor(), lambda: RotatingScene(11, 27, 60.0, min_lux=0.3, max_lux=40.0), 300, {},
                 False),
    "flicker-sine": (lambda: SpikeSensor(), lambda: FlickerScene(StillScene(_texture(12, 40, 0.5, 50.0)), 400.0),
                     300, {}, False),
    "flicker-square-q1": (lambda: SpikeSensor(threshold_electrons=1),
                          lambda: FlickerScene(StillScene(_texture(8, 24, 0.01, 500.0)), 300.0, 0.9, "square"),
                          300, {}, False),
    "numpy-light": (lambda: SpikeSensor(), lambda: TranslatingScene(12, 40, (2000.0, 0.0)), 300,
                    {"compiled_light": False}, False),
    "numpy-light-sampled": (lambda: SpikeSensor(photon_noise=False), lambda: RotatingScene(11, 27, 80.0), 300,
                            {"compiled_light": False, "light_sample_ticks": 4}, False),
    "sampled-ticks": (lambda: SpikeSensor(), lambda: TranslatingScene(12, 40, (2000.0, 0.0)), 300,
                      {"light_sample_ticks": 3}, False),
    "dead-time": (lambda: SpikeSensor(dead_time_s=2e-5), lambda: StillScene(_texture(12, 40, 0.1, 3e3)), 300, {},
                  True),
    "dead-time-readout": (lambda: SpikeSensor(dead_time_s=6e-5, reset="readout"),
                          lambda: StillScene(_texture(12, 40, 0.1, 3e3)), 300, {}, True),
    "dead-time-noise-free": (lambda: SpikeSensor(dead_time_s=3e-5, photon_noise=False),
                             lambda: StillScene(_texture(12, 40, 0.1, 3e3)), 300, {}, True),
    "dead-time-translating": (lambda: SpikeSensor(dead_time_s=2e-5),
                              lambda: TranslatingScene(12, 40, (2000.0, 0.0), max_lux=300.0), 300, {}, True),
}

GOLDEN = {
    'bars-readout': '85d059021e37fb13a1007afa',
    'dead-time': '58a3734de044429f85c6d519',
    'dead-time-noise-free': '1bca44698083e9ef040991b7',
    'dead-time-readout': 'c3f29c4bf85e085402ebb2eb',
    'dead-time-translating': '486a6a63e466abc2e69508d0',
    'fixed-patterns': 'f703ea9a0237202b20921d98',
    'flicker-sine': 'fc06776c3dd8ae24eb520a5d',
    'flicker-square-q1': 'b9d1398c60b4a24cf1ceb9f7',
    'hdr-q1': '8e8fa7add43737cb80d9f2d1',
    'hdr-q100': '3430b2a939d7c40395266c4f',
    'hdr-q2e4': 'fe2aef34fa6b70ec8b8388fa',
    'hdr-q7': '528e93335c2906d0a531b435',
    'hdr-readout': 'd9335a3a3f031b034d3505bf',
    'moving-edge': 'f5c9e31dc6e1d105f309a095',
    'moving-edge-noise-free': 'd0b35f18b828cc4db697ae3a',
    'numpy-light': 'd1f18659a9ef1031fb1ff237',
    'numpy-light-sampled': 'ca97d52fc3101758837dd73b',
    'rotating': '9319207b53484d1b5c4713de',
    'sampled-ticks': '293fed916ebde8026f1819ac',
    'step': '62d8676e08a2b76126e100b5',
    'still-exact': 'e769c5c8245a54366c13289e',
    'still-exact-empty-start': 'f6ae24cfa266faf587dd4208',
    'still-noise-free': '1cb4e6b517ab0fc1155a673e',
    'still-noise-free-empty': '9febe62456ec81517534c9f1',
    'still-noise-free-readout': 'cb111891b9669b241dd2deca',
    'threshold-map': '7ab2eb9a542e5da3c4928bcf',
    'threshold-map-translating': 'fab5083af7d1325d98822a95',
    'translating': '7d581e4c5357ed06c09949fa',
    'translating-noise-free': '048606840d9849f655f14e81',
    'translating-noise-free-readout': 'f1b709bfaa70f0ed6c8c589a',
    'video-hold': '8772d89b865e40f44a61626d',
    'video-linear': 'f331e9e374872d4aa6bd9db7',
    'video-linear-odd': '9a41cbee7a2d5c912ed28408',
}


def _state_for(sensor, scene, twin_state: bool, seed: int):
    height, width = scene.height, scene.width
    if twin_state:  # the same sensor without dead time: its start does not depend on the dead-time law
        from dataclasses import replace

        twin = type(sensor)(replace(sensor.parameters, dead_time_s=0.0))
        return twin.initial_state(height, width, seed)
    return sensor.initial_state(height, width, seed)


def outcome(name: str, block_ticks: int | None = None, seed: int = 11) -> str:
    """Hash of the spikes and of the final state of one case."""
    import contextlib
    from unittest import mock

    from viform.sensors import _spike_kernels

    make_sensor, make_scene, n_ticks, options, twin = CASES[name]
    options = {"light_sample_ticks": 1, **options}  # recorded with light at every tick ("auto" holds moving light)
    sensor, scene = make_sensor(), make_scene()
    state = _state_for(sensor, scene, twin, seed)
    digest = hashlib.blake2b(digest_size=12)
    # dead-time cases: the kernel alone, from the twin's state (the stationary start with dead time,
    # issue 29, is tested in test_spike.py)
    keep = mock.patch.object(_spike_kernels, "_dead_time_stationary_state", lambda *args: None) if twin else \
        contextlib.nullcontext()
    with keep:
        for _, block in sensor.simulate(scene, n_ticks / sensor.parameters.clock_hz, seed=seed, state=state,
                                        block_ticks=block_ticks, **options):
            digest.update(np.packbits(block.reshape(block.shape[0], -1), axis=1).tobytes())
    for array in (state.charge, state.target, state.counter):
        digest.update(np.ascontiguousarray(array, dtype=np.int64).tobytes())
    return digest.hexdigest()


@pytest.mark.parametrize("name", sorted(CASES))
def test_same_bits_and_state_as_before(name):
    assert outcome(name) == GOLDEN[name]


@pytest.mark.parametrize("name", ["hdr-q7", "video-linear-odd", "threshold-map-translating", "dead-time",
                                  "still-noise-free-readout", "numpy-light-sampled"])
def test_same_bits_whatever_the_block_size(name):
    assert outcome(name, block_ticks=37) == GOLDEN[name]


@pytest.mark.parametrize("name", ["hdr-q100", "translating", "still-noise-free"])
def test_same_bits_on_one_thread(name):
    from numba import get_num_threads, set_num_threads

    before = get_num_threads()
    try:
        set_num_threads(1)
        assert outcome(name, block_ticks=101) == GOLDEN[name]
    finally:
        set_num_threads(before)


def _eager(sensor):
    """The same sensor with the saturated-pixel shortcut disabled (every tick drawn as it comes)."""
    eager = type(sensor)(sensor.parameters)
    eager._saturation_bounds = lambda height, width: np.full(height * width, np.iinfo(np.int64).max)
    return eager


@pytest.mark.parametrize("scene", [
    HDRScene(8, 64, 0.01, 7.0),
    StepScene(StillScene(_texture(8, 40, 1e3, 1e5)), 0.003, 1e-4),  # saturated, then dim: the stretch ends
    VideoScene(np.stack([_texture(8, 40, 1e3, 1e5, seed=s) for s in range(4)]), 8000.0, "hold"),
])
def test_saturated_pixels_skipped_then_settled_give_the_same_bits_and_state(scene):
    """Pixels above the saturation bound are only counted (fire every tick) and their draws replayed
    when the light changes or the state is read: the bits and the state equal drawing every tick."""
    sensor = SpikeSensor()
    lazy = np.concatenate([b for _, b in sensor.simulate(scene, 0.006, seed=2, block_ticks=70)])
    reference = _eager(sensor)
    eager = np.concatenate([b for _, b in reference.simulate(scene, 0.006, seed=2, block_ticks=70)])
    assert np.array_equal(lazy, eager)
    assert lazy.mean() > 0.2  # the scene does saturate
    state, eager_state = (s.initial_state(scene.height, scene.width, 2) for s in (sensor, reference))
    for s, st in ((sensor, state), (reference, eager_state)):
        for _ in s.simulate(scene, 0.006, seed=2, block_ticks=70, state=st):
            pass
    for name in ("charge", "target", "counter"):
        assert np.array_equal(getattr(state, name), getattr(eager_state, name))
    assert not state.pending_ticks.any()


def test_saturated_pixels_are_only_counted_in_the_kernel():
    """On a still saturated scene the kernel draws nothing for pixels above the bound: it counts their ticks."""
    from viform.sensors import _spike_kernels as module

    sensor = SpikeSensor()
    scene = HDRScene(4, 64, 0.01, 7.0)
    q, _, index, tables = sensor._pixel_tables(4, 64)
    bounds = sensor._saturation_bounds(4, 64)
    state = sensor.initial_state(4, 64, 1)
    rates = sensor._fixed_point_rates(scene.illuminance_lux(0.0).reshape(1, -1), 4, 64)
    words = np.empty((500, 4), dtype=np.uint64)
    drawn_before = state.counter.copy()
    module._run_block(words.view(np.uint8), rates, np.array([500], np.int64), 0, state.charge, state.target,
                      state.counter, q, index, *tables, *module.fixed_point_tables(tables[0]), state.keys, True,
                      False, 0.0, module.MODE_GENERAL, bounds, state.pending_ticks, state.pending_rate,
                      module.SPARSE_FIRING, module.VECTOR_MIN_SPIKES)
    above = rates[0] >= bounds
    assert above.sum() > 30 and (~above).sum() > 30
    assert np.all(state.pending_ticks[above] == 500) and not state.pending_ticks[~above].any()
    assert np.array_equal(state.counter[above], drawn_before[above])  # nothing drawn for them
    assert np.all(state.counter[~above] >= drawn_before[~above])
    bits = np.unpackbits(words.view(np.uint8), axis=1, count=256, bitorder="little").astype(bool)
    assert bits[:, above].all()


@pytest.mark.parametrize("shape", [(12, 40), (8, 27), (3, 8)])
def test_packed_frames_are_the_dat_layout(shape):
    """simulate_packed gives pack_frames of the bool stream, upright or flipped, for any width."""
    from viform.stream.dat import pack_frames

    sensor = SpikeSensor(threshold_electrons=20)
    scene = TranslatingScene(*shape, (1500.0, 0.0))
    spikes = sensor.capture(scene, 0.004, seed=5).spikes
    for flip in (False, True):
        packed = np.concatenate([b for _, b in sensor.simulate_packed(scene, 0.004, seed=5, block_ticks=53,
                                                                      flip=flip)])
        assert packed.tobytes() == pack_frames(spikes, flip)


@pytest.mark.parametrize("shape", [(12, 40), (8, 32), (3, 8)])
def test_packed_blocks_in_constant_light_are_fresh_arrays(shape):
    """In constant light the kernels write the .dat frames in place: blocks kept past the next one still
    hold their own ticks (none is a view of a reused buffer), upright or flipped, and match the bool stream."""
    from viform.stream.dat import pack_frames

    sensor = SpikeSensor(threshold_electrons=20)
    rng = np.random.default_rng(3)
    scene = StillScene(rng.uniform(0.5, 30.0, shape))
    spikes = sensor.capture(scene, 0.004, seed=5).spikes
    assert spikes.any() and not spikes.all()
    for flip in (False, True):
        blocks = [b for _, b in sensor.simulate_packed(scene, 0.004, seed=5, block_ticks=37, flip=flip)]
        assert len(blocks) == 5
        for i, a in enumerate(blocks):
            assert not any(np.shares_memory(a, b) for b in blocks[i + 1:])
        assert np.concatenate(blocks).tobytes() == pack_frames(spikes, flip)


if __name__ == "__main__":
    names = sys.argv[1:] or sorted(CASES)
    for name in names:
        print(f"    {name!r}: {outcome(name)!r},")


@pytest.mark.parametrize("make_sensor", [
    lambda: SpikeSensor(),
    lambda: SpikeSensor(threshold_electrons=1),
    lambda: SpikeSensor(threshold_electrons=2e4),
    lambda: _MapSensor(),
    lambda: SpikeSensor(reset="readout"),
    lambda: SpikeSensor(dead_time_s=2e-5),
    lambda: SpikeSensor(dead_time_s=5e-5, reset="readout"),
    lambda: SpikeSensor(photon_noise=False),
    lambda: SpikeSensor(photon_noise=False, reset="readout"),
    lambda: SpikeSensor(photon_noise=False, dead_time_s=3e-5),
], ids=["q100", "q1", "q2e4", "threshold-map", "readout", "dead-time", "dead-time-readout", "noise-free",
        "noise-free-readout", "noise-free-dead-time"])
def test_dim_words_run_crossing_by_crossing_give_the_tick_by_tick_bits(make_sensor):
    """The constant-light kernel runs dim words crossing by crossing (``sparse_firing``); forcing that
    path on every word (dark to saturated, several runs of light) or never taking it gives the same
    bits and state, for every crossing rule."""
    from viform.sensors import _spike_kernels as module

    sensor = make_sensor()
    height, width = 6, 40
    lux = _texture(height, width, 0.002, 2e4, seed=9)
    runs = np.stack([lux, lux * 0.01, lux[::-1], np.zeros_like(lux), lux * 3.0]).reshape(5, -1)
    rates = sensor._fixed_point_rates(runs, height, width)
    seg_end = np.array([37, 38, 120, 190, 300], dtype=np.int64)
    q, _, index, tables = sensor._pixel_tables(height, width)
    p = sensor.parameters
    if not p.photon_noise and p.dead_time_s == 0:
        mode = module.MODE_NOISE_FREE_READOUT if p.reset == "readout" else module.MODE_NOISE_FREE_SELF
    else:
        mode = module.MODE_GENERAL
    results = []
    for sparse_firing in (0.0, 1e30):
        state = sensor.initial_state(height, width, 4)
        words = np.empty((300, 4), dtype=np.uint64)
        for first, last in ((0, 100), (100, 300)):  # two blocks: runs cross a block boundary
            block = words[first:last]
            module._run_block(block.view(np.uint8), rates, seg_end, first, state.charge, state.target,
                              state.counter, q, index, *tables, *sensor._fixed_point_tables(height, width),
                              state.keys, p.photon_noise,
                              p.reset == "readout", p.dead_time_s * p.clock_hz, mode,
                              sensor._saturation_bounds(height, width), state.pending_ticks, state.pending_rate,
                              sparse_firing, module.VECTOR_MIN_SPIKES)
        module._settle_all(state.charge, state.target, state.counter, q, index, *tables, state.keys,
                           state.pending_ticks, state.pending_rate)
        results.append((words, state))
    (lanes, lane_state), (sparse, sparse_state) = results
    assert np.array_equal(lanes, sparse)
    for name in ("charge", "target", "counter"):
        assert np.array_equal(getattr(lane_state, name), getattr(sparse_state, name)), name
    bits = np.unpackbits(lanes.view(np.uint8), axis=1, count=height * width, bitorder="little")
    assert bits[190:].mean(axis=0).max() > 0.3  # bright pixels (saturated, or at the dead-time limit)
    firing = bits.mean(axis=0)
    assert ((firing > 0) & (firing < 0.05)).any()  # and dim ones that do fire


@pytest.mark.parametrize("make_sensor", [
    lambda: SpikeSensor(),
    lambda: SpikeSensor(threshold_electrons=1),
    lambda: SpikeSensor(threshold_electrons=2e4),
    lambda: _MapSensor(),
], ids=["q100", "q1", "q2e4", "threshold-map"])
def test_busy_words_fired_eight_lanes_at_a_time_give_the_lane_by_lane_bits(make_sensor):
    """Busy words take their fired lanes' first crossing eight lanes at a time (``vector_min``); sending
    every tick-by-tick word that way, or none, gives the same bits and state from dark to saturated
    light (second crossings in a tick, lanes too far past their target for the eight-lane path,
    saturated lanes left to the lazy count), over several runs and a block boundary."""
    from viform.sensors import _spike_kernels as module

    sensor = make_sensor()
    height, width = 6, 64
    lux = _texture(height, width, 0.002, 2e5, seed=11)
    runs = np.stack([lux, lux * 0.01, lux[::-1], lux * 4.0, lux * 0.2]).reshape(5, -1)
    rates = sensor._fixed_point_rates(runs, height, width)
    seg_end = np.array([40, 41, 150, 230, 320], dtype=np.int64)
    q, _, index, tables = sensor._pixel_tables(height, width)
    p = sensor.parameters
    results = []
    for vector_min in (0.0, np.inf):
        state = sensor.initial_state(height, width, 6)
        words = np.empty((320, 6), dtype=np.uint64)
        for first, last in ((0, 90), (90, 320)):
            module._run_block(words[first:last].view(np.uint8), rates, seg_end, first, state.charge, state.target,
                              state.counter, q, index, *tables, *sensor._fixed_point_tables(height, width),
                              state.keys, p.photon_noise, False, 0.0, module.MODE_GENERAL,
                              sensor._saturation_bounds(height, width), state.pending_ticks, state.pending_rate,
                              0.0, vector_min)
        module._settle_all(state.charge, state.target, state.counter, q, index, *tables, state.keys,
                           state.pending_ticks, state.pending_rate)
        results.append((words, state))
    (vector, vector_state), (lanes, lane_state) = results
    assert np.array_equal(vector, lanes)
    for name in ("charge", "target", "counter"):
        assert np.array_equal(getattr(vector_state, name), getattr(lane_state, name)), name
    bits = np.unpackbits(lanes.view(np.uint8), axis=1, count=height * width, bitorder="little")
    firing = bits.mean(axis=0)
    assert (firing > 0.3).sum() > 20 and ((firing > 0) & (firing < 0.05)).any()  # busy lanes and dim ones


def _eight_lane_cases(n_groups, seed):
    """Random lanes for :func:`_fire8_fast`: four Gamma tables (Q = 1, 2, 100, 2500 e⁻), targets near
    their Q, and charges past them by a little, by about one more target, or too far."""
    from viform.sensors import _spike_kernels as module
    from viform.sensors._gamma import TABLE_SIZE, build_tables

    rng = np.random.default_rng(seed)
    shapes = np.array([1.0, 2.0, 100.0, 2500.0])
    (bins,) = build_tables(shapes)
    scaled, accept = module.fixed_point_tables(bins)
    n = 8 * n_groups
    table = rng.integers(0, shapes.size, n)
    qe = shapes[table]
    fixed = float(1 << 32)
    target = ((0.5 + rng.random(n)) * qe * fixed).astype(np.int64) + 1
    one_by_one = (np.minimum(48.0 * qe, 8.0 * qe * qe) * fixed).astype(np.int64)
    kind = rng.integers(0, 4, n)
    past = np.where(kind == 0, rng.random(n) * 0.2 * qe, np.where(kind == 1, (0.8 + 0.8 * rng.random(n)) * qe,
                                                                  np.where(kind == 2, 0.0, 60.0 * qe)))
    charge = target + np.minimum(past * fixed, 2.0 ** 62).astype(np.int64)
    keys = rng.integers(0, 2 ** 63, n, dtype=np.uint64) * np.uint64(2) + rng.integers(0, 2, n, dtype=np.uint64)
    drawn = rng.integers(0, 10 ** 6, n)
    fired = rng.integers(0, 256, n_groups).astype(np.uint64)
    fired[::17] = 0
    return (charge, target, drawn, keys, (table * TABLE_SIZE).astype(np.int64), one_by_one, scaled,
            np.ascontiguousarray(accept), fired)


def _eight_lane_kernels():
    """(the eight-lane step over groups, the lane loop's first step over the same lanes), compiled."""
    from numba import njit

    from viform.sensors import _spike_kernels as module

    fire8, target_fast = module._fire8_fast, module._target_fast

    @njit
    def eight(c, t, drawn, key, row0, one_by_one, scaled, accept, fired):
        out = np.empty(fired.size, np.uint64)
        for g in range(fired.size):
            out[g] = fire8(c, t, drawn, key, row0, one_by_one, scaled, accept, 8 * g, fired[g])
        return out

    @njit
    def lane_by_lane(c, t, drawn, key, row0, one_by_one, scaled, accept, fired):
        out = np.zeros(fired.size, np.uint64)
        outcomes = np.zeros(5, np.int64)  # accepted, rejected, second crossing, too far, not fired
        for g in range(fired.size):
            for j in range(8):
                i = 8 * g + j
                if not (fired[g] >> np.uint64(j)) & np.uint64(1):
                    outcomes[4] += 1
                    continue
                over = c[i] - t[i]
                if over >= one_by_one[i]:
                    out[g] |= np.uint64(1) << np.uint64(j)
                    outcomes[3] += 1
                    continue
                new = target_fast(row0[i], scaled, accept, key[i], drawn[i])
                c[i] = over
                t[i] = new
                if new != 0:
                    drawn[i] += 1
                if new == 0 or over >= new:
                    out[g] |= np.uint64(1) << np.uint64(8 + j)
                outcomes[0 if new != 0 and over < new else (1 if new == 0 else 2)] += 1
        return out, outcomes

    return eight, lane_by_lane


def _compare_eight_lanes(case):
    """Run both on copies of ``case``; assert the same flags and state; the lane loop's outcome counts."""
    eight, lane_by_lane = _eight_lane_kernels()
    mine = [a.copy() for a in case[:3]]
    theirs = [a.copy() for a in case[:3]]
    flags = eight(*mine, *case[3:])
    expected, outcomes = lane_by_lane(*theirs, *case[3:])
    assert np.array_equal(flags, expected)
    for a, b, name in zip(mine, theirs, ("charge", "target", "counter"), strict=True):
        assert np.array_equal(a, b), name
    return mine, outcomes


def test_eight_lane_first_crossing_is_the_lane_loops_to_the_bit():
    """:func:`_fire8_fast` leaves each lane as the lane loop's first step does (``_target_fast``'s draw,
    its counter, c − t), leaves lanes not fired or too far past their target untouched, and flags the
    lanes the loop must finish; every outcome occurs (an accepted draw, a rejected one, a second
    crossing, a lane too far past its target, a lane not fired)."""
    _, outcomes = _compare_eight_lanes(_eight_lane_cases(4000, seed=5))
    assert (outcomes > 50).all(), outcomes


_GOLDEN_GAMMA = 0x9E3779B97F4A7C15
_MASK64 = (1 << 64) - 1


def _undo_xorshift(y, shift):
    x = y
    for _ in range(64 // shift + 1):
        x = y ^ (x >> shift)
    return x


def _stream_key_for(h, counter):
    """The stream key whose draw ``counter`` hashes to ``h`` (SplitMix64 is a bijection: each step undone)."""
    x = _undo_xorshift(h, 31)
    x = (x * pow(0x94D049BB133111EB, -1, 1 << 64)) & _MASK64
    x = _undo_xorshift(x, 27)
    x = (x * pow(0xBF58476D1CE4E5B9, -1, 1 << 64)) & _MASK64
    x = _undo_xorshift(x, 30)
    return (x - _GOLDEN_GAMMA - counter * _GOLDEN_GAMMA) & _MASK64


def test_eight_lane_first_crossing_at_its_exact_edges():
    """The eight-lane step at the edges random lanes never reach, against the lane loop: a charge exactly at,
    one below and one above the limit past the target; a squeeze uniform exactly at and one below its bin's
    bound (and the open last bin, never accepted); a charge exactly at, below and above the new target; a
    table target that rounds below 1 (kept at 1); counters near 2^63 and keys with the top bit set."""
    from numba import njit

    from viform.sensors import _spike_kernels as module
    from viform.sensors._gamma import TABLE_SIZE, build_tables, splitmix64

    @njit
    def hashed(key, counter):
        return splitmix64(key + np.uint64(counter) * np.uint64(_GOLDEN_GAMMA))

    shapes = np.array([1.0, 3.0, 100.0, 2e4])
    (bins,) = build_tables(shapes)
    scaled, accept = module.fixed_point_tables(bins)
    fixed = float(1 << 32)
    lanes = []  # (charge, target, counter, key, row0, one_by_one)
    for table, qe in enumerate(shapes):
        row0 = table * TABLE_SIZE
        one_by_one = int(min(48.0 * qe, 8.0 * qe * qe) * fixed)
        target = int(qe * fixed)
        for counter in (0, 7, 2 ** 62 + 3, 2 ** 63 - 2):
            for b in (0, 1, TABLE_SIZE // 2, TABLE_SIZE - 2, TABLE_SIZE - 1):
                row = row0 + b
                bound = int(accept[row])
                for low in sorted({0, max(bound - 1, 0), bound}):
                    for mid in (0, 5, (1 << 26) - 1):
                        key = _stream_key_for((b << 54) | (mid << 26) | low, counter)
                        assert int(hashed(np.uint64(key), counter)) == (b << 54) | (mid << 26) | low
                        new = int(module._target_fast(np.int64(row0), scaled, accept, np.uint64(key),
                                                      np.int64(counter)))
                        overs = {0, 1, one_by_one - 1, one_by_one, one_by_one + 1}
                        overs |= {new - 1, new, new + 1} if new > 0 else set()
                        for over in sorted(o for o in overs if o >= 0):
                            lanes.append((target + over, target, counter, key, row0, one_by_one))
    while len(lanes) % 8:
        lanes.append((0, int(np.iinfo(np.int64).max), 0, 0, 0, 0))  # padding: never fires
    columns = list(zip(*lanes, strict=True))
    case = (np.array(columns[0], np.int64), np.array(columns[1], np.int64), np.array(columns[2], np.int64),
            np.array(columns[3], np.uint64), np.array(columns[4], np.int64), np.array(columns[5], np.int64),
            scaled, np.ascontiguousarray(accept), np.full(len(lanes) // 8, 0xFF, np.uint64))
    (_, target_after, _), outcomes = _compare_eight_lanes(case)
    assert (outcomes[:4] > 100).all(), outcomes  # accepted, rejected, second crossing, too far: all at the edges
    clamped = (case[1] != target_after) & (target_after == 1)
    assert clamped.any()  # a drawn target that rounds below one fixed-point unit is kept at 1


@pytest.mark.parametrize("reset", ["self", "readout"])
def test_noise_free_chunks_write_the_dat_frame_bits_of_the_general_lanes(reset):
    """The noise-free modes run busy words in chunks of ticks with the charge in vector registers and write
    each tick's bits straight into the .dat frame (⌈H·W/8⌉ bytes, here ending inside a byte and inside the
    last word); from dark to above one crossing per tick (lanes left to the tick by tick loop), over runs
    and a block boundary, the bits and state equal those of the general lanes (every crossing through
    ``_fire``) written into whole 64-bit words."""
    from viform.sensors import _spike_kernels as module

    sensor = SpikeSensor(photon_noise=False, reset=reset, threshold_electrons=30)
    height, width = 7, 37  # 259 pixels: 33 bytes a tick, the last word one byte
    lux = _texture(height, width, 0.01, 3e5, seed=5)
    # the first two words below one crossing per tick (there the chunks run), the others up to saturation
    one_per_tick = 30.0 / float(sensor.electrons_per_tick(1.0))
    lux.flat[:128] = one_per_tick * np.linspace(0.001, 0.95, 128)
    runs = np.stack([lux, lux * 0.3, lux]).reshape(3, -1)
    rates = sensor._fixed_point_rates(runs, height, width)
    seg_end = np.array([150, 151, 400], dtype=np.int64)
    q, _, index, tables = sensor._pixel_tables(height, width)
    mode = module.MODE_NOISE_FREE_READOUT if reset == "readout" else module.MODE_NOISE_FREE_SELF
    results = []
    for kernel_mode, row_bytes in ((mode, 33), (module.MODE_GENERAL, 40)):
        state = sensor.initial_state(height, width, 2)
        out = np.full((400, row_bytes), 0xAB, dtype=np.uint8)
        for first, last in ((0, 130), (130, 400)):
            module._run_block(out[first:last], rates, seg_end, first, state.charge, state.target, state.counter,
                              q, index, *tables, *sensor._fixed_point_tables(height, width), state.keys, False,
                              reset == "readout", 0.0, kernel_mode, sensor._saturation_bounds(height, width),
                              state.pending_ticks, state.pending_rate, 0.0, module.VECTOR_MIN_SPIKES)
        results.append((out, state))
    (chunks, chunk_state), (general, general_state) = results
    assert np.array_equal(chunks, general[:, :33])
    assert not general[:, 33:].any()  # the padding lanes never fire
    for name in ("charge", "target"):  # (no draws without photon noise: the counter is not read)
        assert np.array_equal(getattr(chunk_state, name), getattr(general_state, name)), name
    firing = np.unpackbits(chunks, axis=1, count=height * width, bitorder="little").mean(axis=0)
    assert firing.max() == 1.0 and 0.0 < firing.min() < 0.01  # saturated and dim pixels both present
