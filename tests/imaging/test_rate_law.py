"""The tick readout's rate law and its inversion (light from firing rates near saturation)."""

import math

import numpy as np
import pytest

from viform.imaging import accumulation_image, interval_image
from viform.imaging.rate_law import electrons_per_tick_from_rate, firing_rate_per_tick
from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor

CLOCK_HZ = 40e3


def _lux_for(sensor, electrons_per_tick):
    p = sensor.parameters
    return (electrons_per_tick * p.clock_hz - p.dark_current_e_per_s) / p.optics.electrons_per_lux_second


@pytest.mark.parametrize("q,per_tick,dead_ticks,reset", [
    (1, 1.0, 0.0, "self"),  # Q·r read −36 %
    (1, 0.05, 0.0, "self"),  # mean interval 20 ticks: Q·r read −2.5 %
    (100, 100.0, 0.0, "self"),  # mean interval 1 tick: Q·r read −4.1 %
    (100, 150.0, 0.3, "self"),  # dead time and saturation
    (100, 40.0, 0.5, "readout"),
])
def test_accumulation_light_inverts_the_rate_law(q, per_tick, dead_ticks, reset):
    """The simulated firing rate follows the law (mean over P independent pixels within 5
    standard errors, std/√P), and the accumulation image's light, the law's inverse of each
    pixel's rate, is unbiased: mean within 5·std(λ̂)/√P plus the inversion's curvature bias
    ½|λ''(r)|·var(r) (delta method) and the table's 1e-5. Q·r, the old light, misses by more."""
    side, n_ticks = 32, 2000
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, dead_time_s=dead_ticks / CLOCK_HZ,
                         reset=reset)
    stream = sensor.capture(StillScene(np.full((side, side), _lux_for(sensor, per_tick))), n_ticks / CLOCK_HZ,
                            seed=3)
    rate = stream.spikes.reshape(n_ticks, -1).mean(axis=0)
    law = float(firing_rate_per_tick(per_tick, q, dead_ticks, reset))
    pixels = side * side
    assert abs(rate.mean() - law) < 5 * rate.std() / math.sqrt(pixels)
    image = accumulation_image(stream, n_ticks / 2 / CLOCK_HZ, n_ticks / CLOCK_HZ)
    assert not image.saturated.any()
    estimate = image.electrons_per_s / CLOCK_HZ
    step = 1e-3 * min(law, 1 - law)
    lam = [float(electrons_per_tick_from_rate(law + k * step, q, dead_ticks, reset)[0]) for k in (-1, 0, 1)]
    curvature = (lam[2] - 2 * lam[1] + lam[0]) / step**2
    tolerance = 5 * estimate.std() / math.sqrt(pixels) + 0.5 * abs(curvature) * rate.var() + 1e-5 * per_tick
    assert abs(estimate.mean() - per_tick) < tolerance, (estimate.mean(), per_tick, tolerance)
    naive = q * rate.mean()
    assert abs(naive - per_tick) > tolerance  # what Q·r gave


@pytest.mark.parametrize("q,dead_ticks,reset,noise", [
    (1, 0.0, "self", True), (100, 0.0, "self", True), (16000, 0.0, "self", True), (100, 0.5, "self", True),
    (100, 2.4, "self", True), (100, 0.0, "self", False), (1, 0.0, "readout", True), (100, 0.7, "readout", True),
])
def test_rate_law_round_trip(q, dead_ticks, reset, noise):
    """Inverse then law gives the rate back (relative 1e-5) from 10⁻⁶ Q to 30 Q e⁻ per tick;
    the self-reset law at d = 0, Q = 1 is 1 − e^(−λ) (Poisson: at least one crossing a tick)."""
    lam = q * np.geomspace(1e-6, 30, 200)
    rate = firing_rate_per_tick(lam, q, dead_ticks, reset, noise)
    back, saturated = electrons_per_tick_from_rate(rate, q, dead_ticks, reset, noise)
    again = firing_rate_per_tick(back, q, dead_ticks, reset, noise)
    ok = ~saturated
    assert ok.sum() > 100
    assert np.allclose(again[ok], rate[ok], rtol=1e-5, atol=0)
    assert np.all(back[saturated] <= lam[saturated] * (1 + 1e-9))  # a lower bound
    if q == 1 and reset == "self" and noise:
        assert np.allclose(rate, -np.expm1(-lam), rtol=1e-12)


def test_saturation_is_flagged_not_clipped():
    """Far above saturation (Q = 1, 40 e⁻ per tick: P(a tick without a crossing) = e^-40) every
    tick fires: the accumulation and interval images flag every pixel saturated and give a
    lower bound of the light, never more than the truth; below the ceiling nothing is flagged."""
    sensor = SpikeSensor(threshold_electrons=1, dark_current_e_per_s=0.0)
    stream = sensor.capture(StillScene(np.full((8, 8), _lux_for(sensor, 40.0))), 200 / CLOCK_HZ, seed=1)
    for image in (accumulation_image(stream, 100 / CLOCK_HZ, 200 / CLOCK_HZ), interval_image(stream, 100 / CLOCK_HZ)):
        assert image.saturated.all()
        assert image.info["rate_law"]["saturated_pixels"] == 64
        assert np.all(image.electrons_per_s <= 40.0 * CLOCK_HZ)
        assert np.all(image.electrons_per_s >= 1.0 * CLOCK_HZ)
    dim = sensor.capture(StillScene(np.full((8, 8), _lux_for(sensor, 0.5))), 200 / CLOCK_HZ, seed=1)
    assert not accumulation_image(dim, 100 / CLOCK_HZ, 200 / CLOCK_HZ).saturated.any()
