"""Global-shutter storage effects (issue 28, seeds 001 and 002): parasitic light sensitivity of
the storage node while rows wait to be read, and storage-node leakage, each measured back from
simulated frames against its closed form across its range."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.scenes import StillScene, VideoScene
from viform.sensors.frame import FramePixelParameters, FrameSensor
from viform.sensors.segmented import SegmentedExposureSensor

H, W = 40, 256
EXPOSURE_S = 1e-3


def _params(**kw):
    base = dict(full_well_electrons=200_000.0, read_noise_electrons=0.0, dsnu_electrons=0.0, prnu_fraction=0.0,
                dark_current_e_per_s=0.0, adc_bits=16, black_offset_dn=16.0, readout_time_s=20e-3)
    base.update(kw)
    return FramePixelParameters(**base)


def _rows_electrons(sensor, scene, seed=1):
    dn = sensor.capture_frame(scene, 0.0, EXPOSURE_S, seed=seed).astype(float)
    p = sensor.parameters
    return ((dn - p.black_offset_dn) / p.system_gain_dn_per_e).mean(axis=1)


@pytest.mark.parametrize("pls", [1e-3, 0.01, 0.1])
def test_shutter_efficiency_is_the_fraction_of_light_leaking_into_the_stored_frame(pls):
    """Dark during the exposure, L lux afterwards: row r holds PLS·η·Φ(L)·w_r with
    w_r = (r + 1)/H · T_read (Poisson). The slope of the row means against w_r, divided by the
    photo-rate, gives back PLS = 1 − shutter efficiency (the LUX13HS's 99 % is PLS = 0.01)."""
    p = _params(parasitic_light_sensitivity=pls)
    lux = 200.0  # PLS = 0.1 then stores ≤ 34,000 e⁻, below the full well
    scene = VideoScene(np.stack([np.zeros((H, W)), np.full((H, W), lux)]), 1 / EXPOSURE_S, interpolation="hold")
    cam = FrameSensor(p, exposure_s=EXPOSURE_S, frame_rate_hz=40.0)
    rows = _rows_electrons(cam, scene)
    wait = (np.arange(H) + 1) / H * p.readout_time_s
    rate = p.optics.electrons_per_s(lux)
    slope = np.polyfit(wait, rows, 1)[0]
    # Poisson: row mean error √(m/W); slope error ≈ that / (std(w)·√H)
    m = pls * rate * wait.mean()
    tol = 5 * np.sqrt(m / W) / (wait.std() * np.sqrt(H)) / rate
    assert slope / rate == pytest.approx(pls, abs=tol + 1e-3 * pls)
    assert p.shutter_efficiency == pytest.approx(1 - pls)
    # light during the exposure only: nothing leaks (the storage node sees the dark)
    lit_then_dark = VideoScene(np.stack([np.full((H, W), lux), np.zeros((H, W))]), 1 / EXPOSURE_S,
                               interpolation="hold")
    rows2 = _rows_electrons(cam, lit_then_dark)
    assert np.ptp(rows2) < 6 * np.sqrt(rate * EXPOSURE_S / W) + 2 / p.system_gain_dn_per_e


@pytest.mark.parametrize("leak", [200.0, 5e4])
def test_storage_leakage_grows_with_the_wait_of_each_row(leak):
    """In the dark, row r holds leak·w_r (Poisson): the slope of the row means is the leakage."""
    p = _params(storage_leakage_e_per_s=leak)
    cam = FrameSensor(p, exposure_s=EXPOSURE_S, frame_rate_hz=40.0)
    rows = _rows_electrons(cam, StillScene(np.zeros((H, W))))
    wait = (np.arange(H) + 1) / H * p.readout_time_s
    slope = np.polyfit(wait, rows, 1)[0]
    tol = 5 * np.sqrt(leak * wait.mean() / W) / (wait.std() * np.sqrt(H)) + 1 / p.system_gain_dn_per_e / 0.02
    assert slope == pytest.approx(leak, abs=tol)


def test_segmented_pixel_has_the_same_storage_node():
    """Seed 001's 5T pixel is a global shutter too: its stored frame gathers the same leak."""
    p = _params(storage_leakage_e_per_s=1e4)
    seg = SegmentedExposureSensor(p, (0.8e-3, 0.2e-3), (50_000.0,), frame_rate_hz=40.0, noise=False)
    rows = _rows_electrons(seg, StillScene(np.zeros((H, W))))
    wait = (np.arange(H) + 1) / H * p.readout_time_s
    np.testing.assert_allclose(rows, 1e4 * wait, atol=1 / p.system_gain_dn_per_e)


def test_storage_defaults_are_off_and_bad_values_named():
    assert FramePixelParameters().readout_time_s == 0 and FramePixelParameters().parasitic_light_sensitivity == 0
    with pytest.raises(ViformError, match="parasitic_light_sensitivity"):
        FramePixelParameters(parasitic_light_sensitivity=1.5)
    with pytest.raises(ViformError, match="storage_leakage_e_per_s"):
        FramePixelParameters(storage_leakage_e_per_s=-1.0)


class _CountingScene(VideoScene):
    """A VideoScene that counts how often the light is looked at."""

    looks = 0

    def illuminance_lux(self, t_s):
        type(self).looks += 1
        return super().illuminance_lux(t_s)


@pytest.mark.parametrize("height", [12, 40])
def test_each_rows_light_is_its_mean_over_its_own_wait(height):
    """Light rising linearly during the readout, L(t) = F₀ + b·t: row r's mean over
    [end, end + w_r] is F₀ + b·(end + w_r/2). With H ≤ samples every wait ends on a segment edge
    (exact, to rounding); with H > samples the segment a wait ends in is taken at its mean, off by
    at most |b|·Δ²/(8·w_r) (Δ = T_read/M). The scene is looked at ``samples`` times, not per row;
    still light gives exactly its value."""
    p = _params(parasitic_light_sensitivity=0.01)
    rng = np.random.default_rng(3)
    f0, f1 = rng.uniform(0, 500, (2, height, 8))
    rate_hz = 1 / 0.05  # frame 1 is at 50 ms, after the 20 ms readout
    scene = _CountingScene(np.stack([f0, f1]), rate_hz, interpolation="linear")
    arr = FrameSensor(p, exposure_s=EXPOSURE_S, frame_rate_hz=40.0).pixel_array(height, 8)
    end = 3e-3
    _CountingScene.looks = 0
    got = arr.storage_light_lux(scene, end, samples=32)
    assert _CountingScene.looks <= 32 + height  # ⌈32/M⌉ per segment: ≤ 32 + M
    wait = arr.storage_wait_s()
    b = (f1 - f0) * rate_hz
    want = f0 + b * (end + wait / 2)
    n_seg = min(height, 32)
    bound = np.abs(b) * (p.readout_time_s / n_seg) ** 2 / (8 * wait) if height > 32 else 0.0
    assert np.all(np.abs(got - want) <= 1e-9 + 1e-12 * np.abs(want) + bound)
    if height > 32:  # the bound is reached somewhere, not vacuous
        assert np.abs(got - want).max() > 0.05 * np.max(bound)
    still = np.abs(f0)
    np.testing.assert_array_equal(arr.storage_light_lux(StillScene(still), end), still)


def test_light_that_starts_mid_readout_reaches_only_the_rows_still_waiting():
    """Dark until half the readout has passed, L lux after: rows read in the first half hold no
    parasitic charge; a later row r holds L·(w_r − T/2)/w_r of mean light (exact: the step lies
    on a segment edge)."""
    p = _params(parasitic_light_sensitivity=0.01)
    lux = 300.0
    half = p.readout_time_s / 2
    end = 1e-3
    frames = np.stack([np.zeros((H, 4)), np.full((H, 4), lux)])
    scene = VideoScene(frames, 1 / (end + half), interpolation="hold")
    arr = FrameSensor(p, exposure_s=EXPOSURE_S, frame_rate_hz=40.0).pixel_array(H, 4)
    got = arr.storage_light_lux(scene, end, samples=8)
    wait = arr.storage_wait_s()
    np.testing.assert_allclose(got, np.broadcast_to(lux * np.clip(wait - half, 0, None) / wait, (H, 4)),
                               atol=1e-9)
