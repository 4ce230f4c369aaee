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


def _mean_tolerance(truth_mean_lux, n_ticks, pixels, k=5.0):
    """k σ of the mean emitted light: per pixel Var(count) ≈ N/Q (Gamma(Q) intervals, seed 000 §5.1)
    + ½ (the phase at both ends), N = λT/Q."""
    n = truth_mean_lux * E_LUX * n_ticks / SENSOR.clock_hz / Q
    sd_count = np.sqrt((n / Q + 0.5) / pixels)
    return k * sd_count / n * truth_mean_lux


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
    tol = 5 * np.sqrt(n_spk / Q + 0.5) / n_spk * expected
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
    # the spike display's error is counting noise: it falls with the window, ~1/√(spikes per window)
    e = d["spike"]["error_rel_rms"]
    assert e["16.7 ms"] < e["4 ms"] < e["1 ms"]
    lam_mean = comparison["true_time_mean_lux"] * E_LUX
    spikes_1ms = lam_mean * 1e-3 / Q
    # Gamma-renewal counts: relative sd ≈ √(N/Q + ½)/N per pixel-window (within a factor 2: the
    # pixels differ in light and the window edges in phase)
    theory = np.sqrt(spikes_1ms / Q + 0.5) / spikes_1ms
    assert 0.5 * theory < e["1 ms"] < 2.0 * theory


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
    """Mean delay = (1 + link)/clock; sd from the count statistics over the windows (≈ 0.35 tick)."""
    for link in (0, 6):
        r = measure_step_latency(link_latency_ticks=link, size=32, seed=11)
        theory = (1 + link) / 40e3
        assert r["latency_theory_s"] == pytest.approx(theory)
        # Var(area) ≈ N_after/Q + 4·N_before/Q + 1 spikes² per pixel (2 frames after at 8 lux, 1 before
        # at 2 lux, the pre level scaled ×2), over 1024 pixels, ÷ the step's 0.43 spikes/tick/pixel
        n_after = 8 * E_LUX * 2 / 60 / Q
        n_before = 2 * E_LUX / 60 / Q
        sd_ticks = np.sqrt((n_after / Q + 4 * n_before / Q + 1) / 1024) / (6 * E_LUX / 40e3 / Q)
        assert abs(r["spike_latency_s"] - theory) * 40e3 < 4 * sd_ticks
        assert r["conventional_latency_s"] == pytest.approx(1 / 60, rel=1e-3)


def test_passthrough_fidelity_beats_the_conventional_pipe():
    r = run_passthrough(seed=2)
    for w, err in r["spike"]["error_rel_rms"].items():
        assert err < 0.1
        assert err < 0.2 * r["conventional"]["error_rel_rms"][w]
    assert r["spike"]["latency_s"] < 1e-3 * r["conventional"]["latency_s"] * 10


def test_bad_display_input():
    with pytest.raises(ViformError, match="refresh_hz"):
        sd.HoldDisplay(0.0)
    with pytest.raises(ViformError, match="content"):
        sd.HoldDisplay(60.0, "crt")
    with pytest.raises(ViformError, match="spikes must have shape"):
        sd.SpikeDisplay().emitted_lux(np.zeros((3, 3), bool))
    with pytest.raises(ViformError, match="TranslatingScene"):
        sd.compare_displays(StillScene(np.ones((4, 4))))
    with pytest.raises(ViformError, match="link_latency_ticks"):
        measure_step_latency(link_latency_ticks=-1)
