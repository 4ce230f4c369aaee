"""Spike-camera DR from intervals (seed 000 §4.2–4.4) and SNR from interval statistics."""

import numpy as np
import pytest

spike = pytest.importorskip("viform.sensors.spike")

from viform.measure.spike_characterization import (  # noqa: E402
    characterize_spike_sensor,
    expected_interval_dynamic_range,
    intervals_ticks,
)


def test_interval_dr_matches_q_over_tau_id():
    """DR = 20 lg(τ̂/τ̌) = 20 lg(Q/(τ̌ I_d)): Q = 100, 40 kHz, I_d = 2000 e⁻/s → 66.02 dB.

    τ̂ is measured from ~1000 dark spikes (±3 %, 0.3 dB); τ̌ from saturating light (1 tick).
    """
    sensor = spike.SpikeSensor(dark_current_e_per_s=2000.0)
    r = characterize_spike_sensor(sensor, height=16, width=16, seed=3)
    assert r["expected"]["dynamic_range_db"] == pytest.approx(66.02, abs=0.01)
    assert abs(r["dynamic_range_db"] - r["expected"]["dynamic_range_db"]) < 1.0
    assert r["shortest_interval_s"] == pytest.approx(25e-6)


def test_seed000_typical_dr_160db():
    """Seed 000 §4.4: τ̌ = 10 ns, τ̂ = 1 s → 160 dB (parameters only)."""
    p = spike.SpikeSensorParameters(threshold_electrons=100, clock_hz=1e8, dark_current_e_per_s=100)
    assert expected_interval_dynamic_range(p)["dynamic_range_db"] == pytest.approx(160.0)


def test_interval_snr_is_sqrt_q_at_low_light():
    """Gamma(Q) intervals: mean/std → √Q = 10 (20 dB) while τ ≫ one tick; lower near τ̌."""
    sensor = spike.SpikeSensor(dark_current_e_per_s=20.0)
    p = sensor.parameters
    lux_one_tick = p.threshold_electrons * p.clock_hz / p.optics.electrons_per_lux_second
    r = characterize_spike_sensor(
        sensor, height=4, width=4, seed=1, dark_duration_s=1.0, lux_values=[lux_one_tick / 200, lux_one_tick / 3]
    )
    snr = r["snr_curve"]["snr"]
    assert snr[0] == pytest.approx(10.0, rel=0.1)
    assert snr[1] < snr[0]


def test_intervals_ticks():
    s = np.zeros((10, 1, 2), bool)
    s[[1, 4, 9], 0, 0] = True
    s[[2], 0, 1] = True
    out = intervals_ticks(s)
    assert len(out) == 1 and out[0].tolist() == [3, 5]
