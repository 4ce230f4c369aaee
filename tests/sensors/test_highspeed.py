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
