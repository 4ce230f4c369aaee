"""Sub-threshold quantization readout (seed 000 §4.5)."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.scenes import StillScene
from viform.sensors.base import Sensor
from viform.sensors.spike import SpikeSensor
from viform.sensors.subthreshold import SubthresholdSpikeSensor, subthreshold_dynamic_range_db


def _lux(sensor, e_per_s):
    return float(sensor.parameters.optics.lux_from_electrons_per_s(e_per_s))


def test_dynamic_range_formula():
    sub = SubthresholdSpikeSensor(SpikeSensor(), sensitivity_ticks=400, levels=100)
    assert sub.dynamic_range_db() == pytest.approx(20 * np.log10(400 * 100))
    # seed 000 §4.5's worked example: τ̌ = 10 ns, τ̆ = 10 ms, N = 100 → 160 dB
    assert subthreshold_dynamic_range_db(10e-9, 10e-3, 100) == pytest.approx(160.0)
    with pytest.raises(ViformError, match="sensitivity_s"):
        subthreshold_dynamic_range_db(1e-3, 1e-4, 10)


def test_is_a_sensor_and_describes_itself():
    """The sub-threshold camera is a :class:`Sensor`: its description holds the spike sensor's
    parameters plus τ̆ and N, and its capture is its native output (spikes plus levels)."""
    sub = SubthresholdSpikeSensor(SpikeSensor(threshold_electrons=50.0), sensitivity_ticks=10, levels=8)
    assert isinstance(sub, Sensor)
    d = sub.describe()
    assert d["threshold_electrons"] == 50.0 and d["sensitivity_ticks"] == 10 and d["subthreshold_levels"] == 8
    cap = sub.capture(StillScene(np.full((4, 8), 10.0)), 0.001, seed=1)
    assert cap.levels.shape == (cap.spikes.n_ticks // 10 + 1, 4, 8)


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


def _capture_at(q, electrons_per_window, levels, window_ticks=20, size=32, duration_s=0.05, seed=3):
    s = SpikeSensor(dark_current_e_per_s=0.0, threshold_electrons=q)
    e_per_s = electrons_per_window * s.parameters.clock_hz / window_ticks
    sub = SubthresholdSpikeSensor(s, sensitivity_ticks=window_ticks, levels=levels)
    return sub.capture(StillScene(np.full((size, size), _lux(s, e_per_s))), duration_s, seed=seed)


@pytest.mark.parametrize("q", [3, 100, 10_000])
@pytest.mark.parametrize("lam", [0.5, 2.0])
def test_unquantized_charge_balance_is_the_poisson_count(q, lam):
    """≤ 2 e⁻ per read window, N = Q levels (one level per electron): the window's charge
    balance Q·spikes + n_end − n_start is the number of electrons that arrived in it, a
    Poisson(λ) count. Over n = 102,400 independent windows the sample mean has standard
    error √(λ/n) and the sample variance √((λ + 2λ²)/n) (Poisson fourth moment); both are
    checked at 4.5 standard errors, and P(0) = e^-λ at 4.5·√(p(1−p)/n). The old readout
    (a fresh binomial at every read) gave mean 3.37 and variance 16 at λ = 2, Q = 100.
    """
    cap = _capture_at(q, lam, levels=q)
    n = cap.electrons_per_s() * cap.sensitivity_s
    size = n.size
    assert size == 102_400
    assert np.allclose(n, np.rint(n))  # whole electrons
    assert abs(n.mean() - lam) < 4.5 * np.sqrt(lam / size)
    assert abs(n.var() - lam) < 4.5 * np.sqrt((lam + 2 * lam**2) / size)
    p0 = np.exp(-lam)
    assert abs((np.rint(n) == 0).mean() - p0) < 4.5 * np.sqrt(p0 * (1 - p0) / size)


@pytest.mark.parametrize("levels", [10, 100])
def test_reads_never_decrease_within_an_interval(levels):
    """Within one interval the read charge is a counting process: a window without a spike
    never reads a lower level at its end than at its start (the old readout did in 31 % of
    them); and quantized levels (N < Q) stay unbiased: a pixel's window estimates sum to
    its exact electron count minus r_end − r_start, the rounding of its last and first
    reads (each in [0, Q/N)), so their mean is the light within 4.5 Poisson standard
    errors √(λ/n) plus at most (Q/N) / (windows per pixel)."""
    cap = _capture_at(100, 2.0, levels=levels)
    counts = cap.window_counts()
    lv = cap.levels[: counts.shape[0] + 1]
    quiet = counts == 0
    assert quiet.mean() > 0.9
    assert np.all(lv[1:][quiet] >= lv[:-1][quiet])
    n = cap.electrons_per_s() * cap.sensitivity_s
    assert np.all(n >= 0)
    runs = n.shape[0]
    assert abs(n.mean() - 2.0) < 4.5 * np.sqrt(2.0 / n.size) + (100 / levels) / runs


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
