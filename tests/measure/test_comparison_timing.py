"""The comparison's time resolution and latency follow the sensor's physics.

A spike pixel integrates until it holds Q electrons: its integration time is its interval
τ = Q/(η·E + I_dark) (seed 000 §3.3), so at fixed light it falls in proportion to Q. The
interval that contains a chosen instant is length-biased — its mean is E[τ²]/E[τ] = τ̄·(1 + 1/Q)
for Gamma(Q) intervals — a bias of 1 % at Q = 100, well inside the tolerance below.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from viform.light.scenes import StillScene, TranslatingScene
from viform.measure import comparison as cmp
from viform.sensors.spike import SpikeSensor

#: Uniform light, lux, and the instants scored (s); the clip is long enough for every interval to close.
LUX, INSTANTS, CLIP_S = 0.25, (0.04, 0.05, 0.06), 0.1


def _timing(q: float, scene=None):
    sensor = SpikeSensor(threshold_electrons=q)
    scene = scene if scene is not None else StillScene(np.full((32, 48), LUX))
    stream = sensor.capture(scene, CLIP_S, seed=11)
    return sensor, cmp.spike_timing(stream, scene, INSTANTS)


@pytest.mark.parametrize("q", [100.0, 400.0, 1600.0])
def test_spike_integration_time_is_the_pixels_interval(q):
    """The median interval at the scored instants is Q/(η·E + I_dark), within 5 % (tick rounding of a
    ≥ 20-tick interval ±2.5 %, length bias 1/Q, the median of 1 536 Gamma(Q) draws ≪ 1 %)."""
    sensor, (resolution, latency, intervals) = _timing(q)
    p = sensor.parameters
    expected = q / (p.optics.electrons_per_lux_second * LUX + p.dark_current_e_per_s)
    assert expected * p.clock_hz >= 20  # many ticks: the tolerance's premise
    assert resolution == pytest.approx(expected, rel=0.05)
    assert latency == pytest.approx(resolution + 1 / p.clock_hz)
    assert len(intervals) == len(INSTANTS) and intervals[0].shape == (32, 48)


def test_time_resolution_falls_as_q_falls_at_fixed_light():
    """At fixed light, each halving of Q halves the integration time (and the latency with it): a
    time-resolution demand can be met by lowering the threshold."""
    res = [_timing(q)[1][0] for q in (1600.0, 800.0, 400.0, 200.0)]
    for a, b in zip(res, res[1:], strict=False):
        assert b < a and b / a == pytest.approx(0.5, rel=0.08)


def test_every_reconstruction_reports_the_sensors_timing():
    """The time resolution is the sensor's: the three reconstructions of one stream report the same value,
    taken over the pixels where the scene moves (a translating texture: every pixel moves)."""
    scene = TranslatingScene(32, 48, (2000.0, 0.0), max_lux=40.0)
    shots = cmp.shoot("spikeone", scene, 0.03, [0.01, 0.02], seed=1)
    assert {s.key for s in shots} >= {"spikeone-accumulation", "spikeone-interval"}
    values = {s.time_resolution_s for s in shots}
    assert len(values) == 1 and math.isfinite(values.pop())
    assert all(s.latency_s == pytest.approx(s.time_resolution_s + 1 / 40e3) for s in shots)
    for s in shots:
        assert all(e.integration_s is not None and e.integration_s.shape == (32, 48) for e in s.estimates)


def test_moving_pixels_fall_back_to_every_pixel():
    still = StillScene(np.full((8, 12), 3.0))
    assert cmp.moving_pixels(still, 0.0, (8, 12)).all()
    moving = TranslatingScene(8, 12, (2000.0, 0.0))
    mask = cmp.moving_pixels(moving, 0.001, (8, 12))
    assert mask.shape == (8, 12) and mask.any()
