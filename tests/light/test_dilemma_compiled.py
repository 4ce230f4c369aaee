"""The comparison scenes' light in compiled code: the same light and the same spike bits as the NumPy path."""

import numpy as np
import pytest

from viform.light.catalog import builtin_scene
from viform.light.compiled import evaluate
from viform.sensors.spike import SpikeSensor


@pytest.mark.parametrize("shape", [(32, 48), (40, 100)])
def test_dilemma_compiled_light_is_the_scene_light(shape):
    """Every part (vehicle, blades, blob, LED) at instants spread over two LED periods and a vehicle pass."""
    scene = builtin_scene("dilemma", *shape)
    light = scene.compiled_light()
    assert light is not None and light.kind == "dilemma"
    times = (np.arange(0, 900, 7) + 0.5) / 40e3
    truth = scene.illuminance_lux_many(times)
    assert np.array_equal(evaluate(light, times), truth)
    assert light.lux_max >= truth.max()
    # the moving parts and the LED's two states are all in these instants
    assert len(np.unique(truth[:, scene.led].mean(axis=1))) == 2
    covered = (truth[:, scene.vehicle_rows[0], :] == scene.vehicle_lux).sum(axis=1)  # vehicle columns in view
    assert covered.min() < covered.max()
    assert (truth != scene._background).sum(axis=(1, 2)).min() > 0


@pytest.mark.parametrize("name", ["dilemma", "night-road-fog"])
def test_compiled_scene_gives_the_numpy_path_bits(name):
    """Same seed, same bits as the NumPy light path, whatever the block size and light-sample grid
    (a brightness of 0.02 keeps every part, the lamp too, below the chip's ceiling)."""
    scene = builtin_scene(name, 32, 48, brightness=0.02)
    sensor = SpikeSensor(gain_spread_fraction=0.05, dark_current_spread_fraction=0.3, threshold_electrons=50)
    duration = 600 / 40e3
    fast = sensor.capture(scene, duration, seed=11, block_ticks=600).spikes
    numpy_path = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=11, compiled_light=False)])
    assert np.array_equal(fast, numpy_path)
    assert np.array_equal(fast, sensor.capture(scene, duration, seed=11, block_ticks=37).spikes)
    held = sensor.capture(scene, duration, seed=11, block_ticks=53, light_sample_ticks=3).spikes
    held_numpy = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=11, light_sample_ticks=3,
                                                               compiled_light=False)])
    assert np.array_equal(held, held_numpy)
    assert 0.005 < fast.mean() < 0.9
