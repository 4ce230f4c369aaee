"""Spike continuous display vs sample-and-hold displays, and the pass-through (seed 000 §7)."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.display import spike_display as sd
from viform.display.passthrough import measure_step_latency, run_passthrough
from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor, SpikeSensorParameters

SENSOR = SpikeSensorParameters()
Q = 100
E_LUX = SENSOR.optics.electrons_per_lux_second


@pytest.fixture(scope="module")
def comparison():
    return sd.compare_displays(keep_arrays=True, seed=0)


def _count_sd(n_spikes):
    """σ of one pixel's count of mean ``n_spikes``: Var = N/Q (Gamma(Q) intervals, seed 000 §5.1)
    + 1/6 (uniform phase at both ends; measured within 3 % for N = 3…215)."""
    return np.sqrt(n_spikes / Q + 1 / 6)


def _mean_tolerance(truth_mean_lux, n_ticks, pixels, k=5.0):
    """k σ of the mean emitted light over ``pixels`` independent pixels (Var linear in N)."""
    n = truth_mean_lux * E_LUX * n_ticks / SENSOR.clock_hz / Q
    return k * _count_sd(n) / np.sqrt(pixels) / n * truth_mean_lux


def test_time_averaged_light_equals_the_source_still():
    scene = StillScene(np.linspace(0.5, 10.0, 16 * 16).reshape(16, 16))
    n = 4000
    spikes = SpikeSensor(SENSOR).capture(scene, n / SENSOR.clock_hz, seed=3).spikes
    disp = sd.SpikeDisplay.for_sensor(SENSOR)
    emitted = disp.emitted_lux(spikes)[1:]  # one tick of display delay
    # per pixel: the mean over 0.1 s equals the source (+ dark bias) within the count statistics
    per_pixel = emitted.mean(axis=0, dtype=np.float64)
    expected = scene.illuminance_lux(0) + disp.dark_bias_lux
    n_spk = expected * E_LUX * (n - 1) / SENSOR.clock_hz / Q
    tol = 5 * _count_sd(n_spk) / n_spk * expected
    assert np.all(np.abs(per_pixel - expected) < tol)
    assert abs(per_pixel.mean() - expected.mean()) < _mean_tolerance(expected.mean(), n - 1, 256)


def test_time_averaged_light_equals_the_source_moving(comparison):
    a = comparison["arrays"]
    truth, spike = a["truth"], a["spike"]
    bias = comparison["spike_display_dark_bias_lux"]
    got = float(spike[1:].mean(dtype=np.float64))
    want = float(truth[:-1].mean(dtype=np.float64)) + bias
    assert abs(got - want) < _mean_tolerance(want, truth.shape[0] - 1, truth.shape[1] * truth.shape[2])


def test_hold_display_frames_repeat_the_same_light():
    scene = sd.moving_bars_scene(height=2, width=64)
    e = sd.HoldDisplay(60.0).emitted_lux(scene, 1334, 40e3)
    assert np.array_equal(e[0], e[665])  # same frame for 1/60 s
    assert not np.array_equal(e[0], e[667])
    np.testing.assert_allclose(e[0], scene.illuminance_lux(0.0))


def test_spike_display_error_is_far_below_hold_displays(comparison):
    d = comparison["displays"]
    for w in ("1 ms", "4 ms", "16.7 ms"):
        assert d["spike"]["error_rel_rms"][w] < 0.2 * d["hold 120 Hz"]["error_rel_rms"][w]
        assert d["hold 120 Hz"]["error_rel_rms"][w] < d["hold 60 Hz"]["error_rel_rms"][w]
    # the spike display's error is counting noise, √(N̄/Q + 1/6)/N̄ (Gamma(Q) intervals, seed 000 §5.1,
    # plus a uniform phase at both window edges). Corrections, all within 5 %: the RMS pools ≥ 3
    # windows × 2048 pixels (sampling error ≤ 1/√(2·6144) ≈ 1 %); the one-tick display delay adds
    # (7 lux / mean)·√(crossings per window)/ticks per window in quadrature (+2 % at 16.7 ms); the
    # dim pixels' 3 spikes per ms are not yet phase-smeared, so their edge term is f(1−f) < 1/6
    # (−3 % at 1 ms). A "+½" edge term would be 47 % high at 1 ms, Poisson counts (1/√N̄) 6× high.
    e = d["spike"]["error_rel_rms"]
    assert e["16.7 ms"] < e["4 ms"] < e["1 ms"]
    for w, theory in d["spike"]["error_rel_rms_theory"].items():
        assert e[w] == pytest.approx(theory, rel=0.05)


def test_tracking_eye_edge_width_matches_theory(comparison):
    d = comparison["displays"]
    v = comparison["scene"]["velocity_px_per_s"]
    for f in (60.0, 120.0):
        width = d[f"hold {f:g} Hz"]["tracked_edge_width_px"]
        # 0.8·v/f, plus at most the 1-px linear interpolation between pixel centres
        assert sd.hold_edge_width_theory_px(v, f) - 0.2 < width < sd.hold_edge_width_theory_px(v, f) + 1.0
    # the spike display is as sharp as the scene itself (the interpolation's ~1 px)
    assert d["spike"]["tracked_edge_width_px"] < d["truth"]["tracked_edge_width_px"] + 0.5
    assert d["spike"]["tracked_edge_width_px"] < 0.25 * d["hold 60 Hz"]["tracked_edge_width_px"]


def test_tracked_profile_of_a_still_edge_on_a_static_display():
    # a static display and an eye at rest: the profile is the row itself
    e = np.zeros((10, 3, 20), np.float32)
    e[:, :, 10:] = 1.0
    u, prof = sd.tracked_profile(e, 40e3, 0.0, 0, 10)
    assert sd.edge_width_px(u, prof, 0.0, 1.0, 9.5, 5.0) == pytest.approx(0.8, abs=0.11)


def test_passthrough_latency_matches_theory():
    """Mean delay = (1 + link)/clock (the firing rate follows λ(t)/Q at once, the display shows a
    spike during the tick after its readout), within 4σ of the count statistics (σ ≈ 0.05 tick, so
    a delay off by a quarter tick fails)."""
    for link in (0, 6):
        r = measure_step_latency(link_latency_ticks=link, size=32, seed=11)
        theory = (1 + link) / 40e3
        assert r["latency_theory_s"] == pytest.approx(theory)
        # area = S·Δ − (C_after − r·C_pre) spikes per pixel, r = settle/pre: Var = N_after/Q + r²N_pre/Q
        # + the phases at the three window edges, (1 + (1 + r)² + r²)/12; over 1024 pixels, ÷ the
        # step's spikes per tick per pixel
        settle, pre = r["spike_settle_ticks"], r["pre_ticks"]
        ratio = settle / pre
        per_tick = E_LUX / 40e3 / Q
        var = (8 * per_tick * settle / Q + ratio ** 2 * 2 * per_tick * pre / Q
               + (1 + (1 + ratio) ** 2 + ratio ** 2) / 12)
        sd_ticks = np.sqrt(var / 1024) / (6 * per_tick)
        assert abs(r["spike_latency_s"] - theory) * 40e3 < 4 * sd_ticks
        assert 4 * sd_ticks < 0.25
        assert r["conventional_latency_s"] == pytest.approx(1 / 60, rel=1e-3)


def test_passthrough_fidelity_beats_the_conventional_pipe():
    r = run_passthrough(seed=2)
    for w, err in r["spike"]["error_rel_rms"].items():
        assert err < 0.1
        assert err < 0.2 * r["conventional"]["error_rel_rms"][w]
    assert r["spike"]["latency_s"] < 0.01 * r["conventional"]["latency_s"]


def test_bad_display_input():
    with pytest.raises(ViformError, match="refresh_hz"):
        sd.HoldDisplay(0.0)
    with pytest.raises(ViformError, match="content"):
        sd.HoldDisplay(60.0, "crt")
    with pytest.raises(ViformError, match="spikes must have shape"):
        sd.SpikeDisplay().emitted_lux(np.zeros((3, 3), bool))
    with pytest.raises(ViformError, match="velocity_px_per_s = 0 "):
        sd.compare_displays(sd.moving_bars_scene(velocity_px_per_s=0.0))
    with pytest.raises(ViformError, match="at most 660 px/s"):
        sd.compare_displays(sd.moving_bars_scene(velocity_px_per_s=3000.0))
    with pytest.raises(ViformError, match="TranslatingScene"):
        sd.compare_displays(StillScene(np.ones((4, 4))))
    with pytest.raises(ViformError, match="link_latency_ticks"):
        measure_step_latency(link_latency_ticks=-1)
