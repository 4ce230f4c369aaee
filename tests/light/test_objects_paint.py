"""The multi-object scene's compiled painting (viform.light._objects_paint): the scene's NumPy light to the bit."""

import numpy as np
import pytest

from viform.light._objects_paint import ObjectsSampler
from viform.light.multi_object import MultiObjectScene


@pytest.mark.parametrize("options", [{}, {"height": 37, "width": 61, "speed": 2.7, "brightness": 3.0},
                                     {"background": "plain", "t_ref_s": 0.01}])
def test_compiled_painting_is_the_numpy_light_to_the_bit(options):
    """Lux and charge per tick at instants before, through and after every object's crossing (objects entering,
    leaving, hidden), rendered in one batch as the simulator asks: equal to ``illuminance_lux`` bit for bit, and
    the canvas is the background again afterwards."""
    scene = MultiObjectScene(**{"height": 250, "width": 400, **options})
    sampler = scene.compiled_light().sampler
    assert isinstance(sampler, ObjectsSampler)
    times = np.concatenate([(np.arange(0, 2400, 7) + 0.5) / 40e3, np.linspace(-0.02, 0.09, 41)])
    frames = sampler.frames(times)
    for got, t in zip(frames, times, strict=True):
        assert np.array_equal(got, scene.illuminance_lux(float(t)))
    height, width = scene.shape
    rng = np.random.default_rng(5)
    a, b = rng.uniform(0.5, 3.0, height * width), rng.uniform(0.0, 2.0, height * width)
    starts, stops = np.array([0, 3 * width + 5], np.int64), np.array([width, height * width - 7], np.int64)
    pixels = np.concatenate([np.arange(s, e) for s, e in zip(starts, stops, strict=True)])
    rates = np.empty((times.size, pixels.size), np.int64)
    sampler.render(times, starts, stops, a[pixels], b[pixels], rates)
    for got, t in zip(rates, times, strict=True):
        lux = scene.illuminance_lux(float(t)).ravel()[pixels]
        assert np.array_equal(got, np.rint(lux * a[pixels] + b[pixels]).astype(np.int64))
    assert np.array_equal(sampler._canvas, sampler.background)
