"""The high-speed camera as a sensor: 8-bit frames with the exposure auto-exposure gave each (seed 002)."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.isp.highspeed_pipeline import HighSpeedConfig, run_highspeed
from viform.light.scenes import StillScene, TranslatingScene
from viform.sensors.base import Sensor
from viform.sensors.highspeed import HighSpeedCamera


def test_capture_is_the_sensor_part_of_the_pipeline():
    """``capture`` gives every frame that ends in the clip, on the readout clock, with its exposure;
    the pipeline's frames are the same frames (one loop for both)."""
    cam = HighSpeedCamera()
    assert isinstance(cam, Sensor)
    assert cam.frame_rate_hz == pytest.approx(100e6 / 60_000)  # seed 002: 60 000 cycles a frame at 100 MHz
    scene = TranslatingScene(9, 16)
    stack = cam.capture(scene, 0.01, seed=3)
    n = int(np.floor(0.01 * cam.frame_rate_hz))
    assert len(stack) == n and stack.frames_dn.dtype == np.uint8
    cycles = stack.metadata["exposure_cycles"]
    assert np.allclose(stack.exposure_s, cycles / 100e6)
    assert np.allclose(stack.start_times_s + stack.exposure_s, (np.arange(n) + 1) / cam.frame_rate_hz)
    run = run_highspeed(scene, HighSpeedConfig(n_frames=n, seed=3))
    assert np.array_equal(run.gray8, stack.frames_dn) and np.array_equal(run.exposure_cycles, cycles)


def test_auto_exposure_finds_the_target_and_fixed_exposure_stays():
    """On a still scene the AE brings the mean gray into 128 ± 15 and keeps it; without AE the
    exposure never changes."""
    scene = StillScene(np.full((8, 8), 300.0))
    on = HighSpeedCamera().capture_frames(scene, 40, seed=1)
    gray = on.metadata["metered_gray"]
    assert abs(gray[-1] - 128) <= 15 and abs(gray[0] - 128) > 15
    off = HighSpeedCamera(ae=False, exposure_s=200e-6).capture_frames(scene, 5, seed=1)
    assert np.all(off.exposure_s == off.exposure_s[0]) and off.exposure_s[0] == pytest.approx(200e-6)


@pytest.mark.parametrize("kw, needle", [({"target_gray": 300.0}, "target_gray"), ({"meter": "median"}, "meter"),
                                        ({"exposure_s": -1.0}, "exposure_s"), ({"mode": "fast"}, "mode")])
def test_bad_settings_are_refused_when_built(kw, needle):
    with pytest.raises(ViformError, match=needle):
        HighSpeedCamera(**kw)


def test_the_shutter_lets_one_percent_through_while_rows_wait_to_be_read():
    """Seed 002 Table 1: 99 % shutter efficiency. The preset's pixel carries PLS = 0.01 and the
    camera's readout time is the window's (57 600 cycles at 100 MHz = 576 µs for 1280 × 720).
    A frame of still uniform light at 10 µs exposure, noise-free pixel (no read noise, DSNU,
    PRNU or dark current; 16-bit ADC so nothing is clipped): row r of H gathers the extra
    PLS·rate·(r + 1)/H·T_read, so the rows' mean charge rises linearly down the frame with slope
    PLS·rate·T_read/H and the mean parasitic share is PLS·w̄/(t + PLS·w̄); each row within 5 Poisson
    σ (the only noise left is shot noise and the ADC's rounding). The camera's own 8-bit frames at
    1 µs carry the same share (within the 8-bit levels' 10 %)."""
    from viform.isp.highspeed_pipeline import shutter_figures, simulated_parasitic_share
    from viform.sensors.highspeed import lux13hs_pixel_parameters
    from viform.sensors.highspeed_timing import lux13hs_timing

    assert lux13hs_pixel_parameters().parasitic_light_sensitivity == 0.01
    cam = HighSpeedCamera()
    assert cam.parameters.readout_time_s == pytest.approx(57_600 / 100e6)
    h, w, lux, t = 36, 64, 200.0, 10e-6
    px = lux13hs_pixel_parameters(read_noise_electrons=0.0, dsnu_electrons=0.0, dark_current_e_per_s=0.0,
                                  prnu_fraction=0.0, adc_bits=16, adc_range_v=1.2, black_offset_dn=8.0)
    cam = HighSpeedCamera(px, ae=False, exposure_s=t)
    # the camera's frames carry it: at 1 µs the parasitic light is ≈ 3/4 of the signal
    scene = StillScene(np.full((h, w), 3000.0))
    grays = [HighSpeedCamera(lux13hs_pixel_parameters(parasitic_light_sensitivity=pls), ae=False, exposure_s=1e-6)
             .capture_frames(scene, 1, seed=3).frames_dn.astype(float).mean() - 2.0 for pls in (0.0, 0.01)]
    with_pls = 0.01 * 576e-6 * (h + 1) / (2 * h)
    assert grays[1] / grays[0] == pytest.approx((1e-6 + with_pls) / 1e-6, rel=0.1)
    from viform.sensors.frame import FrameSensor

    gain = cam.parameters.system_gain_dn_per_e
    arr = FrameSensor(cam.parameters, exposure_s=t, frame_rate_hz=cam.frame_rate_hz).pixel_array(h, w)
    rng = arr.rng(3, 0)
    scene = StillScene(np.full((h, w), lux))
    electrons = arr.collect_electrons(scene.mean_illuminance_lux(0.0, t), t, rng)
    electrons = electrons + arr.storage_electrons(scene, t, rng)
    dn = arr.digitize(electrons, rng).astype(float)
    rows = (dn - 8.0).mean(axis=1) / gain
    rate = px.optics.electrons_per_s(lux)
    wait = (np.arange(1, h + 1) / h) * cam.parameters.readout_time_s
    expected = rate * (t + 0.01 * wait)
    sigma = np.sqrt(expected / w + 1 / (12 * gain**2 * w))
    assert np.all(np.abs(rows - expected) <= 5 * sigma)
    slope = np.polyfit(np.arange(h), rows, 1)[0]
    assert slope == pytest.approx(0.01 * rate * cam.parameters.readout_time_s / h, rel=0.1)
    fig = shutter_figures(lux13hs_timing("reduced"), "1280x720")
    share = simulated_parasitic_share(t, lux, (h, w))
    predicted = 0.01 * cam.parameters.readout_time_s * (h + 1) / (2 * h)
    assert share == pytest.approx(predicted / (t + predicted), abs=5 * np.sqrt(1 / (rate * t * h * w)))
    assert fig["brightest_lux_shortest_exposure"]["with_parasitic_light"] < \
        fig["brightest_lux_shortest_exposure"]["without_parasitic_light"] / 100
