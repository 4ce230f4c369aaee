"""Golden hashes of whole simulated spike streams: the same command and seed give the same bits.

Unlike ``test_spike_kernel.py`` (the kernel alone, from a given state), each case here runs the
public path end to end — fixed patterns, the stationary start (with dead time too), the run plan,
the kernels, the packed output — and hashes the spikes of every tick and the pixels' final state
(charge, target, draw counter). The cases span Q from 1 to 2^26 e⁻, dark to saturated light,
both reset modes, dead time, noise-free and exact models, threshold spread and every light path
(still, runs of frames, per-tick compiled light, NumPy light). Refactors and speed-ups of the
kernels must reproduce them bit for bit; a change of the random streams must come as a new
sampler version with these kept selectable.

The moving scenes run at one light sample per tick (their "auto" holds the light longer); "held-translating"
holds it over 5 ticks through the per-tick kernel, recorded before that kernel reused a held sample's charge.

Regenerate (only for a deliberate change of the streams): ``python tests/sensors/test_spike_golden.py``.
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


def _texture(height, width, lo_lux, hi_lux, seed=3):
    rng = np.random.default_rng(seed)
    return lo_lux * (hi_lux / lo_lux) ** rng.random((height, width))


def _lux_for(electrons_per_tick):
    return electrons_per_tick / E_PER_LUX_TICK


#: Light at every tick's middle: the moving scenes' "auto" holds the light longer (see the cases' scenes).
_PER_TICK = {"light_sample_ticks": 1}

# name: (sensor factory, scene factory, ticks, simulate options)
CASES = {
    "q1-hdr": (lambda: SpikeSensor(threshold_electrons=1), lambda: HDRScene(8, 16, 0.001, 8.0), 160, {}),
    "q3-translating": (lambda: SpikeSensor(threshold_electrons=3),
                       lambda: TranslatingScene(8, 24, (3000.0, 700.0), pattern="edge", min_lux=_lux_for(0.05),
                                                max_lux=_lux_for(30.0)), 160, _PER_TICK),
    "q100-still": (lambda: SpikeSensor(), lambda: StillScene(_texture(8, 24, 0.05, 300.0)), 200, {}),
    "q100-saturated": (lambda: SpikeSensor(), lambda: StillScene(_texture(8, 16, 10.0, 3e6)), 200, {}),
    "q100-empty-start": (lambda: SpikeSensor(random_initial_charge=False),
                         lambda: StillScene(_texture(8, 16, 0.5, 30.0)), 200, {}),
    "q100-readout-hdr": (lambda: SpikeSensor(reset="readout"), lambda: HDRScene(8, 16, 0.01, 7.0), 200, {}),
    "q16250-chip-translating": (lambda: SpikeSensor(threshold_electrons=16250.0),
                                lambda: TranslatingScene(8, 24, (2000.0, 0.0), min_lux=_lux_for(100.0),
                                                         max_lux=_lux_for(3e4)), 200, _PER_TICK),
    "q2e4-spread-video": (lambda: SpikeSensor(threshold_electrons=2e4, threshold_spread_fraction=0.1),
                          lambda: VideoScene(_lux_for(2e3) * (0.5 + np.random.default_rng(4).random((5, 8, 16))),
                                             2500.0, "hold"), 200, {}),
    "q2e26-huge": (lambda: SpikeSensor(threshold_electrons=2.0 ** 26),
                   lambda: StillScene(_texture(4, 16, _lux_for(2.0 ** 26 / 60), _lux_for(2.0 ** 26 * 3))), 120, {}),
    "noise-free-self": (lambda: SpikeSensor(photon_noise=False), lambda: StillScene(_texture(8, 24, 0.01, 900.0)),
                        200, {}),
    "noise-free-readout": (lambda: SpikeSensor(photon_noise=False, reset="readout"),
                           lambda: RotatingScene(8, 24, 60.0, min_lux=_lux_for(1.0), max_lux=_lux_for(120.0)),
                           200, _PER_TICK),
    "dead-time-self": (lambda: SpikeSensor(dead_time_s=2e-5), lambda: StillScene(_texture(8, 24, 0.1, 3e3)), 200,
                       {}),
    "dead-time-readout": (lambda: SpikeSensor(dead_time_s=6e-5, reset="readout"),
                          lambda: StillScene(_texture(8, 24, 0.1, 3e3)), 200, {}),
    "dead-time-noise-free": (lambda: SpikeSensor(dead_time_s=3e-5, photon_noise=False),
                             lambda: StepScene(StillScene(_texture(8, 16, 0.1, 3e3)), 0.002, 5.0), 200, {}),
    "fixed-patterns-flicker": (lambda: SpikeSensor(gain_spread_fraction=0.2, dark_current_spread_fraction=1.0,
                                                   hot_pixel_fraction=0.1, hot_pixel_dark_current_e_per_s=3e5),
                               lambda: FlickerScene(StillScene(_texture(8, 16, 0.5, 50.0)), 400.0), 200, _PER_TICK),
    "held-translating": (lambda: SpikeSensor(threshold_electrons=20, gain_spread_fraction=0.1),
                         lambda: TranslatingScene(8, 24, (4000.0, 900.0), min_lux=_lux_for(0.5),
                                                  max_lux=_lux_for(60.0)), 200, {"light_sample_ticks": 5}),
    "numpy-light-sampled": (lambda: SpikeSensor(threshold_electrons=40),
                            lambda: TranslatingScene(8, 24, (2000.0, 0.0), min_lux=_lux_for(0.2),
                                                     max_lux=_lux_for(60.0)), 200,
                            {"compiled_light": False, "light_sample_ticks": 3}),
}

GOLDEN = {
    'dead-time-noise-free': 'a7aad8dfdd3527e4c554c0a1',
    'dead-time-readout': '5bd55f405fcbc5ce8f6f929d',
    'dead-time-self': '4f1433844c05074a813ea26c',
    'fixed-patterns-flicker': '1258cc93562d625a7218758d',
    'held-translating': '9dddfe10ac2a310b6482cda1',
    'noise-free-readout': '3f7faad647fe147730414065',
    'noise-free-self': '195f6c21ecd723808c967074',
    'numpy-light-sampled': 'c37c9d3f47e107637c1182f5',
    'q1-hdr': '01c4c49c3518a17bc3e86a42',
    'q100-empty-start': 'cfa2b8c20830553cbc5d429b',
    'q100-readout-hdr': 'c9a8b4cd95f16c80a544eb3d',
    'q100-saturated': '539e2d8b95eea3e026022936',
    'q100-still': 'fed66bc1159117b9f5919ec4',
    'q16250-chip-translating': '58a9a26935534da3d195adfd',
    'q2e26-huge': '1edafbf9e506bef47eda8599',
    'q2e4-spread-video': 'ec51e2e5f9f448fac8f1d146',
    'q3-translating': 'a4a29e839d4071843ea998b2',
}


def outcome(name: str, block_ticks: int | None = None, seed: int = 7) -> str:
    """Hash of the spikes (packed, every tick) and the final state of one case, from a fresh start."""
    make_sensor, make_scene, n_ticks, options = CASES[name]
    sensor, scene = make_sensor(), make_scene()
    state = sensor.initial_state(scene.height, scene.width, seed)
    digest = hashlib.blake2b(digest_size=12)
    for _, block in sensor.simulate(scene, n_ticks / sensor.parameters.clock_hz, seed=seed, state=state,
                                    block_ticks=block_ticks, **options):
        digest.update(np.packbits(block.reshape(block.shape[0], -1), axis=1).tobytes())
    for array in (state.charge, state.target, state.counter):
        digest.update(np.ascontiguousarray(array, dtype=np.int64).tobytes())
    return digest.hexdigest()


def packed_outcome(name: str, seed: int = 7) -> str:
    """Hash of the ``.dat`` frames (rows flipped, as the cameras write) of one case."""
    make_sensor, make_scene, n_ticks, options = CASES[name]
    sensor, scene = make_sensor(), make_scene()
    digest = hashlib.blake2b(digest_size=12)
    for _, frames in sensor.simulate_packed(scene, n_ticks / sensor.parameters.clock_hz, seed=seed, flip=True,
                                            **options):
        digest.update(frames.tobytes())
    return digest.hexdigest()


PACKED_GOLDEN = {
    'q100-still': '609d333b9ac742e760d512e2',
    'q16250-chip-translating': '6394cb566d6d3290e8e0f74b',
    'noise-free-readout': 'b1b7896d9a3e7f5b75cc740c',
    'dead-time-self': 'be5345ccde787bc4ab8c81be',
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_stream_and_state_are_the_golden_ones(name):
    assert outcome(name) == GOLDEN[name]


@pytest.mark.parametrize("name", sorted(PACKED_GOLDEN))
def test_packed_frames_are_the_golden_ones(name):
    assert packed_outcome(name) == PACKED_GOLDEN[name]


def test_cases_span_dark_to_saturated():
    """The cases are not degenerate: together they hold dim pixels and pixels that fire every tick."""
    make_sensor, make_scene, n_ticks, _ = CASES["q100-saturated"]
    stream = make_sensor().capture(make_scene(), n_ticks / 40e3, seed=7)
    per_pixel = stream.spikes.mean(axis=0)
    assert per_pixel.max() == 1.0 and per_pixel.min() < 0.9
    make_sensor, make_scene, n_ticks, _ = CASES["q2e26-huge"]
    stream = make_sensor().capture(make_scene(), n_ticks / 40e3, seed=7)
    assert 0 < stream.spikes.mean() < 0.5


if __name__ == "__main__":
    names = sys.argv[1:] or sorted(CASES)
    print("GOLDEN = {")
    for name in names:
        print(f"    {name!r}: {outcome(name)!r},")
    print("}\nPACKED_GOLDEN = {")
    for name in ("q100-still", "q16250-chip-translating", "noise-free-readout", "dead-time-self"):
        print(f"    {name!r}: {packed_outcome(name)!r},")
    print("}")
