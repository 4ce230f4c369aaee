"""Sub-threshold quantization readout (seed 000 §4.5)."""

import numpy as np
import pytest

from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor
from viform.sensors.subthreshold import SubthresholdSpikeSensor


def _lux(sensor, e_per_s):
    return float(sensor.parameters.optics.lux_from_electrons_per_s(e_per_s))


def test_dynamic_range_formula():
    sub = SubthresholdSpikeSensor(SpikeSensor(), sensitivity_ticks=400, levels=100)
    assert sub.dynamic_range_db() == pytest.approx(20 * np.log10(400 * 100))


def test_dim_light_is_measured_below_one_spike_per_window():
    """20 e⁻ per τ̆ window (Q = 100): spikes alone are mostly silent; the readout is unbiased.

    Charge balance is exact up to the quantization step Q/N, so the mean over pixels and
    windows matches the light within 4 standard errors (Poisson: √20 e⁻ per window).
    """
    s = SpikeSensor(dark_current_e_per_s=0.0)
    sub = SubthresholdSpikeSensor(s, sensitivity_ticks=400, levels=100)
    cap = sub.capture(StillScene(np.full((24, 24), _lux(s, 2000.0))), 0.2, seed=3)
    e = cap.electrons_per_s()
    n = e.size
    assert abs(e.mean() - 2000.0) < 4 * (np.sqrt(20.0) / 0.01) / np.sqrt(n) + 100 / 100 / 0.01
    spikes_only = cap.spike_only_electrons_per_s()
    assert e.std() < 0.3 * spikes_only.std()  # far less noisy than counting spikes in τ̆
    assert (cap.window_counts() == 0).mean() > 0.7


def test_spikes_unchanged_by_readout():
    s = SpikeSensor()
    scene = StillScene(np.full((8, 8), _lux(s, 4e5)))
    cap = SubthresholdSpikeSensor(s, 50, 16).capture(scene, 0.01, seed=9)
    plain = s.capture(scene, 0.01, seed=9)
    assert np.array_equal(cap.spikes.spikes, plain.spikes)


def test_levels_floor_at_weakest_light():
    """Below Q/(N·τ̆) a window may read no level change: the seed's lower limit of DR."""
    s = SpikeSensor(dark_current_e_per_s=0.0, photon_noise=False, random_initial_charge=False)
    sub = SubthresholdSpikeSensor(s, sensitivity_ticks=100, levels=10)
    # Q/(N·τ̆) = 100/(10·2.5 ms) = 4000 e⁻/s: half of it gives a step only every other window
    cap = sub.capture(StillScene(np.full((2, 2), _lux(s, 2000.0))), 0.1, seed=0)
    e = cap.electrons_per_s()
    assert set(np.unique(e.round())) <= {0.0, 4000.0}
    assert e.mean() == pytest.approx(2000.0, rel=0.1)
