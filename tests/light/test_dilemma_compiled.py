"""The built-in scenes' compiled light: the same light and the same spike bits as the NumPy path."""

import numpy as np
import pytest

from viform.light.catalog import builtin_scene
from viform.light.sampled import PaintedSampler, rects_to_words
from viform.sensors.spike import SpikeSensor

PAINTED = ["dilemma", "multi-object", "waving-hand"]


def _static(scene):
    return scene.compiled_light().sampler.static_lux()


@pytest.mark.parametrize("name", PAINTED)
@pytest.mark.parametrize("shape", [(32, 48), (40, 100), (250, 400)])
def test_painted_light_is_the_scene_light(name, shape):
    """Rendered per sample (background once, parts painted in their boxes, boxes restored), the light is the
    scene's NumPy light to the bit at instants spread over two LED periods, a vehicle pass, the objects'
    crossings and a hand wave; nothing outside the dirty rectangles differs from the static light."""
    scene = builtin_scene(name, *shape)
    light = scene.compiled_light()
    assert light is not None and light.kind == "sampled" and isinstance(light.sampler, PaintedSampler)
    sampler = light.sampler
    span, step = (12000, 97) if name == "waving-hand" else (2000, 7)
    times = (np.arange(0, span, step * (4 if shape[0] > 100 else 1)) + 0.5) / 40e3
    truth = scene.illuminance_lux_many(times)
    assert np.array_equal(sampler.frames(times), truth)  # one canvas over all instants: every box restored
    assert sampler.lux_max >= truth.max()
    height, width = shape
    static = _static(scene)
    moved = 0
    for t, frame in zip(times[::3], truth[::3], strict=True):
        inside = np.zeros(height * width, bool)
        inside[rects_to_words(sampler.dirty_rects(np.array([t])), height, width, 1)] = True
        changed = (frame != static).ravel()
        assert not (changed & ~inside).any()
        moved += changed.sum()
    assert moved > 0  # the parts do move through the field
    if name == "dilemma":  # every part is in these instants: the LED's two states, the vehicle entering
        assert len(np.unique(truth[:, scene.led].mean(axis=1))) == 2
        covered = (truth[:, scene.vehicle_rows[0], :] == scene.vehicle_lux).sum(axis=1)
        assert covered.min() < covered.max()


@pytest.mark.parametrize("name", PAINTED)
def test_auto_light_sample_bounds_the_motion(name):
    """Held over the auto sample, the fastest part moves at most 2 × 0.25 px (the bound of sampled.py)."""
    scene = builtin_scene(name, 250, 400)
    ticks = scene.auto_light_sample_ticks(40e3)
    assert ticks >= 2
    assert scene.max_speed_px_per_s() * ticks / 40e3 <= 0.5 + 1e-12
    assert scene.max_speed_px_per_s() * (ticks + 1) / 40e3 > 0.5 or ticks == 64


@pytest.mark.parametrize("name", ["dilemma", "night-road-fog", "multi-object", "waving-hand"])
def test_compiled_scene_gives_the_numpy_path_bits(name):
    """Same seed, same bits as the NumPy light path, whatever the block size and light-sample grid
    (a brightness of 0.02 keeps every part of the dilemma, the lamp too, below the chip's ceiling)."""
    options = {"brightness": 0.02} if name in ("dilemma", "night-road-fog") else {}
    scene = builtin_scene(name, 32, 48, **options)
    sensor = SpikeSensor(gain_spread_fraction=0.05, dark_current_spread_fraction=0.3,
                         threshold_electrons=50 if name != "waving-hand" else 3000)
    duration = 600 / 40e3
    fast = sensor.capture(scene, duration, seed=11, block_ticks=600, light_sample_ticks=1).spikes
    numpy_path = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=11, compiled_light=False,
                                                               light_sample_ticks=1)])
    assert np.array_equal(fast, numpy_path)
    assert np.array_equal(fast, sensor.capture(scene, duration, seed=11, block_ticks=37, light_sample_ticks=1).spikes)
    held = sensor.capture(scene, duration, seed=11, block_ticks=53, light_sample_ticks=3).spikes
    held_numpy = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=11, light_sample_ticks=3,
                                                               compiled_light=False)])
    assert np.array_equal(held, held_numpy)
    assert 0.005 < fast.mean() < 0.9
