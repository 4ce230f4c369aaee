"""Readout timing of the LUX13HS from its clocks (seed 002 §2.1, §3.1.1)."""

import pytest

from viform._validate import ViformError
from viform.sensors.highspeed_timing import (
    SEED_ROI,
    ReadoutTiming,
    Window,
    lux13hs_timing,
)


def test_seed_reduced_mode_1280x720_is_60000_cycles_1666_fps():
    """Seed 002 §3.1.1: 320 cycles a row, 57 600 data cycles, 60 000 a frame → 1 666 fps."""
    t = lux13hs_timing("reduced")
    assert t.cycles_per_row(SEED_ROI) == 320
    assert t.data_cycles(SEED_ROI) == 57_600
    assert t.cycles_per_frame(SEED_ROI) == 60_000
    assert t.frame_rate_hz(SEED_ROI) == pytest.approx(1e8 / 6e4)
    assert int(t.frame_rate_hz(SEED_ROI)) == 1666


def test_normal_mode_full_frame_reaches_3500_fps():
    """Seed 002 §2.1: 1280 × 864 at up to 3 500 fps (normal mode, 8 px/clock, 133 MHz)."""
    t = lux13hs_timing("normal")
    assert t.frame_rate_hz() >= 3500
    # ... and not wildly above: the model keeps the seed's 24 µs overhead.
    assert t.frame_rate_hz() < 3600


def test_reduced_mode_reaches_2500_fps_at_full_frame():
    """Seed 002 §2.2: in reduced mode the core clock is half the clock, so it is "no longer
    bound by the maximum clock" and the rate "can reach 2 500 fps" (more than half of normal
    mode). Model: the 166 MHz limit applies to the core clock; 2 500 fps on the full
    1280 × 864 frame needs a 183.8 MHz pixel clock (core 91.9 MHz), which is accepted. At
    166 MHz the full frame gives 2 271 fps. The seed gives no reduced-mode clock, so the
    clock is derived from the 2 500 fps (tolerance: rounding of the overhead cycles)."""
    t = lux13hs_timing("reduced", pixel_clock_hz=166e6)
    assert t.frame_rate_hz() == pytest.approx(2271, abs=1)
    assert t.frame_rate_hz() > lux13hs_timing("normal").frame_rate_hz() / 2
    f = lux13hs_timing("reduced").clock_for_frame_rate_hz(2500.0)
    assert f == pytest.approx(183.8e6, rel=1e-3) and f > 166e6
    t25 = lux13hs_timing("reduced", pixel_clock_hz=f)
    assert t25.core_clock_hz < t25.max_clock_hz
    assert t25.frame_rate_hz() == pytest.approx(2500, rel=1e-4)
    # Normal mode has no divider: the same clock is refused there.
    with pytest.raises(ViformError, match="pixel_clock_hz"):
        lux13hs_timing("normal", pixel_clock_hz=f)


def test_roi_raises_frame_rate_as_the_formula_says():
    t = lux13hs_timing("reduced")
    rates = [t.frame_rate_hz(Window(0, 0, h, 1280)) for h in (864, 720, 480, 240, 64)]
    assert all(a < b for a, b in zip(rates[:-1], rates[1:], strict=True))
    w = Window(0, 0, 240, 640)
    assert t.cycles_per_frame(w) == (640 // 4) * (240 // 4) + 2400


def test_exposure_is_whole_cycles_bounded_by_the_frame():
    t = lux13hs_timing("reduced")
    assert t.exposure_cycles(100e-6, SEED_ROI) == 10_000
    assert t.max_exposure_cycles(SEED_ROI) == 59_999
    with pytest.raises(ViformError, match="exposure_s"):
        t.exposure_cycles(1e-3, SEED_ROI)  # 1 ms > 600 µs frame
    with pytest.raises(ViformError, match="exposure_cycles"):
        t.check_exposure_cycles(60_000, SEED_ROI)


@pytest.mark.parametrize("roi", ["1400x720", "0,800,1280,100", "-2,0,10,10", "0,0,0,10"])
def test_window_outside_sensor_names_roi(roi):
    with pytest.raises(ViformError, match="roi"):
        lux13hs_timing().window(roi)


def test_bad_roi_text_and_clock():
    with pytest.raises(ViformError, match="roi"):
        lux13hs_timing().window("big")
    with pytest.raises(ViformError, match="pixel_clock_hz"):
        ReadoutTiming(pixel_clock_hz=200e6)
    with pytest.raises(ViformError, match="mode"):
        lux13hs_timing("turbo")


def test_centred_roi_parse():
    w = Window.parse("1280x720", 864, 1280)
    assert (w.row0, w.col0, w.height, w.width) == (72, 0, 720, 1280)
    w = Window.parse("10,20,300,200", 864, 1280)
    assert (w.row0, w.col0, w.height, w.width) == (20, 10, 200, 300)
