"""Spikes of every built-in scene, hashed: recorded before the scene catalogue became data, so that a
built-in scene rendered from its description keeps its bits where its light is the same expression (light
evaluated at every tick's middle: "auto" may hold a moving scene's light longer)."""

import hashlib

import numpy as np
import pytest

from viform.light.catalog import builtin_scene
from viform.sensors.spike import SpikeSensor

#: name → (parameters, threshold Q e⁻ giving ≈ 0.15 spikes a tick at the median light, sha256[:16] of the bits)
GOLDEN = {
    "translating": ({}, 70.0, "3dd25e991c5ebf5b"),
    "moving-edge": ({}, 100.0, "f017c2c3ee5c3650"),
    "rotating": ({}, 105.0, "69e5de398cca26e4"),
    "hdr": ({}, 4772.0, "3432bbfaa44c2646"),
    "step": ({"step_time_s": 0.002, "factor": 8.0}, 48.0, "2796b5bf9bec1d2a"),
    "flicker": ({"frequency_hz": 700.0}, 48.0, "5202305fdd4a8245"),
    "dilemma": ({}, 123.0, "1bd81703b4b1738a"),
    "night-road-fog": ({}, 53.0, "85928311773ad663"),
    "waving-hand": ({}, 4686.0, "33550c8cd28894d1"),
    "multi-object": ({}, 253.0, "c97b23a14b7fbe3d"),
}


@pytest.mark.parametrize("name", list(GOLDEN))
def test_builtin_scene_spikes_are_unchanged(name):
    parameters, q, digest = GOLDEN[name]
    scene = builtin_scene(name, 40, 56, **parameters)
    sensor = SpikeSensor(threshold_electrons=q, gain_spread_fraction=0.05)
    spikes = sensor.capture(scene, 200 / 40e3, seed=3, light_sample_ticks=1).spikes  # the light of every tick
    assert 0.01 < spikes.mean() < 0.9  # the hash covers a stream that fires
    assert hashlib.sha256(np.packbits(spikes).tobytes()).hexdigest()[:16] == digest
