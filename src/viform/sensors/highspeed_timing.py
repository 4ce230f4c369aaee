"""Readout timing of a high-frame-rate global-shutter CMOS sensor from its clocks (seed 002).

Seed 002 (LUX13HS high-frame-rate camera), §2.2 and §3.1.1: the sensor addresses its rows in
pairs (one binary row address = two consecutive rows); a *top* and a *bottom* readout block
convert and output different addresses at the same time, so four rows leave the sensor
together, each at ``pixels_per_clock`` pixels per clock. One frame therefore takes

    cycles_per_frame = ceil(W / pixels_per_clock) · ceil(H / (rows_per_address · readouts))
                       + frame_overhead_cycles                                   (T1)

    frame_rate_hz = pixel_clock_hz / cycles_per_frame                             (T2)

Seed 002 §3.1.1 (reduced mode, 100 MHz, 4 pixels per clock, 1280 × 720): 1280 / 4 = 320
cycles a row, 320 · 720 / 4 = 57 600 cycles a frame, rounded up to 60 000 cycles to leave
time to transfer the charge out of the pixel and clear the previous integration
(2 400 overhead cycles = 24 µs), so 100 MHz / 60 000 ≈ 1 666 fps.

A region of interest (ROI) reads fewer rows and columns, so (T1) shrinks and the frame rate
rises. The exposure is ``N`` whole clock cycles with 1 ≤ N < cycles_per_frame (seed 002
§3.2.4: the AB_n gate is held for N periods T_H; N is any positive integer below the
frame's cycle count), so exposure overlaps the readout of the previous frame (the pixel has
an in-pixel storage node SG, seed 002 §2.2).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
)

#: Active array of the LUX13HS (seed 002, Table 1), rows × columns.
LUX13HS_HEIGHT = 864
LUX13HS_WIDTH = 1280
#: Maximum core clock of the LUX13HS (seed 002 §2.1).
LUX13HS_MAX_CLOCK_HZ = 166e6
#: "Regular" clock of the LUX13HS (seed 002, Table 1).
LUX13HS_NORMAL_CLOCK_HZ = 133e6
#: Charge-transfer / reset time the seed reserves per frame: 2 400 cycles at 100 MHz.
LUX13HS_FRAME_OVERHEAD_S = 2_400 / 100e6


@dataclass(frozen=True)
class Window:
    """A readout window (region of interest) on the sensor, in pixels.

    Attributes
    ----------
    row0, col0 : int
        Top-left corner (0-based).
    height, width : int
        Size in rows and columns.
    """

    row0: int
    col0: int
    height: int
    width: int

    @classmethod
    def parse(cls, text: str, sensor_height: int, sensor_width: int) -> Window:
        """``"WxH"`` (centred) or ``"X,Y,W,H"`` (top-left column, row, width, height)."""
        s = str(text).strip().lower()
        try:
            if "," in s:
                x, y, w, h = (int(v) for v in s.split(","))
                return cls(y, x, h, w)
            w, h = (int(v) for v in s.split("x"))
        except ValueError:
            raise ViformError(f"roi = {text!r} is not allowed: write WxH (centred) or "
                              "X,Y,W,H") from None
        return cls((sensor_height - h) // 2 // 2 * 2, (sensor_width - w) // 2, h, w)

    def check_inside(self, sensor_height: int, sensor_width: int) -> Window:
        """Raise :class:`ViformError` (naming ``roi``) unless the window lies on the sensor."""
        if self.height < 1 or self.width < 1:
            raise ViformError(f"roi = {self.width}x{self.height} is not allowed: width and height "
                              "must be ≥ 1 pixel")
        if (self.row0 < 0 or self.col0 < 0 or self.row0 + self.height > sensor_height
                or self.col0 + self.width > sensor_width):
            raise ViformError(
                f"roi = columns {self.col0}..{self.col0 + self.width - 1}, rows {self.row0}.."
                f"{self.row0 + self.height - 1} is not allowed: it must lie inside the "
                f"{sensor_width}x{sensor_height} (WxH) sensor")
        return self

    @property
    def pixels(self) -> int:
        return self.height * self.width


@dataclass(frozen=True)
class ReadoutTiming:
    """Clock-level readout timing of a row-pair-addressed sensor (seed 002 §3.1.1, eqs. (T1), (T2)).

    Attributes
    ----------
    pixel_clock_hz : float
        Master (data) clock, Hz.
    pixels_per_clock : int
        Pixels each output row delivers per clock.
    rows_per_address : int
        Rows selected by one row address (2 on the LUX13HS).
    parallel_readouts : int
        Readout blocks working on different addresses at once (top + bottom = 2).
    frame_overhead_cycles : int
        Cycles per frame beyond the data (charge transfer, reset, address settling).
    sensor_height, sensor_width : int
        Active array, rows and columns.
    max_clock_hz : float
        Highest *core* clock the sensor accepts (166 MHz on the LUX13HS).
    core_clock_divider : int
        Core clock = ``pixel_clock_hz / core_clock_divider``. 1 in normal mode; 2 in reduced
        mode, where the seed says the core runs at half the clock and is therefore no longer
        bound by the maximum clock (seed 002 §2.2).
    mode : str
        Label (``"normal"``/``"reduced"``).
    """

    pixel_clock_hz: float = 100e6
    pixels_per_clock: int = 4
    rows_per_address: int = 2
    parallel_readouts: int = 2
    frame_overhead_cycles: int = 2_400
    sensor_height: int = LUX13HS_HEIGHT
    sensor_width: int = LUX13HS_WIDTH
    max_clock_hz: float = LUX13HS_MAX_CLOCK_HZ
    mode: str = "reduced"
    core_clock_divider: int = 1

    def __post_init__(self):
        check_positive("pixel_clock_hz", self.pixel_clock_hz)
        check_positive("max_clock_hz", self.max_clock_hz)
        check_int("core_clock_divider", self.core_clock_divider, 1)
        if self.core_clock_hz > self.max_clock_hz * (1 + 1e-12):
            raise ViformError(f"pixel_clock_hz = {self.pixel_clock_hz:g} is not allowed: "
                              f"the sensor's core runs at 1/{self.core_clock_divider} of it and its "
                              f"maximum core clock is {self.max_clock_hz:g} Hz (pixel clock ≤ "
                              f"{self.max_clock_hz * self.core_clock_divider:g} Hz)")
        check_int("pixels_per_clock", self.pixels_per_clock, 1)
        check_int("rows_per_address", self.rows_per_address, 1)
        check_int("parallel_readouts", self.parallel_readouts, 1)
        check_int("frame_overhead_cycles", self.frame_overhead_cycles, 0)
        check_int("sensor_height", self.sensor_height, 1)
        check_int("sensor_width", self.sensor_width, 1)

    @property
    def core_clock_hz(self) -> float:
        """Clock of the sensor core: ``pixel_clock_hz / core_clock_divider``."""
        return self.pixel_clock_hz / self.core_clock_divider

    # ------------------------------------------------------------------ geometry
    @property
    def full_window(self) -> Window:
        return Window(0, 0, self.sensor_height, self.sensor_width)

    def window(self, roi: Window | str | None = None) -> Window:
        """The readout window (full frame when None), checked to lie on the sensor."""
        if roi is None:
            return self.full_window
        if isinstance(roi, str):
            roi = Window.parse(roi, self.sensor_height, self.sensor_width)
        return roi.check_inside(self.sensor_height, self.sensor_width)

    @property
    def rows_per_step(self) -> int:
        """Rows leaving the sensor together: rows_per_address × parallel_readouts (4)."""
        return self.rows_per_address * self.parallel_readouts

    # ------------------------------------------------------------------ timing
    def cycles_per_row(self, roi: Window | str | None = None) -> int:
        """Clock cycles to output one row of the window: ceil(W / pixels_per_clock)."""
        return math.ceil(self.window(roi).width / self.pixels_per_clock)

    def data_cycles(self, roi: Window | str | None = None) -> int:
        """Cycles carrying pixel data, first term of (T1) (57 600 for 1280 × 720, reduced mode)."""
        w = self.window(roi)
        return self.cycles_per_row(w) * math.ceil(w.height / self.rows_per_step)

    def cycles_per_frame(self, roi: Window | str | None = None) -> int:
        """Clock cycles per frame, (T1) (60 000 for the seed's 1280 × 720 reduced mode)."""
        return self.data_cycles(roi) + self.frame_overhead_cycles

    def readout_time_s(self, roi: Window | str | None = None) -> float:
        """Time to read the window out after the frame transfer, s: its data cycles / clock (576 µs
        for 1280 × 720 at 100 MHz). Row r of H waits ≈ (r + 1)/H of it in its storage node (SG,
        seed 002 §2.2), where the shutter's parasitic light reaches it (Table 1: 99 % shutter
        efficiency)."""
        return self.data_cycles(roi) / self.pixel_clock_hz

    def frame_period_s(self, roi: Window | str | None = None) -> float:
        return self.cycles_per_frame(roi) / self.pixel_clock_hz

    def frame_rate_hz(self, roi: Window | str | None = None) -> float:
        """Frames per second, (T2): pixel_clock_hz / cycles_per_frame."""
        return self.pixel_clock_hz / self.cycles_per_frame(roi)

    @property
    def clock_period_s(self) -> float:
        """T_H, one clock period (the exposure quantum, seed 002 §3.2.4)."""
        return 1.0 / self.pixel_clock_hz

    def max_exposure_cycles(self, roi: Window | str | None = None) -> int:
        """Largest exposure, cycles: the frame's cycle count − 1 (seed 002 §3.2.4)."""
        return self.cycles_per_frame(roi) - 1

    def exposure_cycles(self, exposure_s: float, roi: Window | str | None = None) -> int:
        """Whole clock cycles nearest ``exposure_s``, checked against the frame period."""
        check_positive("exposure_s", exposure_s)
        n = max(1, round(exposure_s * self.pixel_clock_hz))
        n_max = self.max_exposure_cycles(roi)
        if n > n_max:
            raise ViformError(
                f"exposure_s = {exposure_s:g} is not allowed: it is longer than the frame "
                f"({n} > {n_max} cycles = {n_max / self.pixel_clock_hz:g} s at "
                f"{self.frame_rate_hz(roi):.1f} fps)")
        return n

    def check_exposure_cycles(self, cycles: int, roi: Window | str | None = None) -> int:
        """``cycles`` must be a whole number in [1, cycles_per_frame − 1]."""
        return check_int("exposure_cycles", cycles, 1, self.max_exposure_cycles(roi))

    def clock_for_frame_rate_hz(self, frame_rate_hz: float, roi: Window | str | None = None,
                                overhead_s: float = LUX13HS_FRAME_OVERHEAD_S) -> float:
        """Pixel clock at which the window runs at ``frame_rate_hz``, inverting (T1)–(T2)
        with the overhead held at ``overhead_s`` (the seed's 24 µs):
        f = fps · data_cycles / (1 − fps · overhead_s)."""
        fps = check_positive("frame_rate_hz", frame_rate_hz)
        if fps * overhead_s >= 1:
            raise ViformError(f"frame_rate_hz = {fps:g} is not allowed: the {overhead_s * 1e6:g} µs "
                              "per-frame overhead alone limits the rate to "
                              f"{1 / overhead_s:g} fps")
        return fps * self.data_cycles(roi) / (1.0 - fps * overhead_s)

    def pixel_rate_per_s(self) -> float:
        """Peak pixel throughput of the output, pixels/s."""
        return self.pixel_clock_hz * self.pixels_per_clock * self.rows_per_step

    def summary(self, roi: Window | str | None = None) -> dict:
        w = self.window(roi)
        return {**asdict(self), "core_clock_hz": self.core_clock_hz, "roi": asdict(w),
                "cycles_per_row": self.cycles_per_row(w),
                "data_cycles": self.data_cycles(w), "cycles_per_frame": self.cycles_per_frame(w),
                "frame_period_s": self.frame_period_s(w), "frame_rate_hz": self.frame_rate_hz(w),
                "max_exposure_s": self.max_exposure_cycles(w) / self.pixel_clock_hz}


def lux13hs_timing(mode: str = "reduced", pixel_clock_hz: float | None = None,
                   frame_overhead_cycles: int | None = None) -> ReadoutTiming:
    """The LUX13HS readout (seed 002 §2.1, §3.1.1).

    ``"reduced"``: 40 LVDS outputs, 4 pixels per clock per row; default clock 100 MHz and
    the seed's 2 400 overhead cycles (60 000-cycle frame at 1280 × 720 → 1 666.7 fps).

    In reduced mode the core clock is half the pixel clock (``core_clock_divider = 2``), so
    the 166 MHz core limit allows pixel clocks up to 332 MHz; the seed's "up to 2 500 fps"
    at the full 1280 × 864 frame needs 183.8 MHz (core 91.9 MHz), which the model now
    accepts (seed 002 §2.2). The seed gives no reduced-mode clock, so the default stays at
    its 100 MHz operating point; the LVDS outputs then carry 4 bits a clock each, 735 Mb/s
    per pair at 183.8 MHz (not a limit the seed states).

    ``"normal"``: 80 LVDS outputs, 8 pixels per clock per row, at the Table-1 regular clock
    133 MHz. The seed gives no overhead for this mode; we keep the seed's 24 µs of charge
    transfer/reset (3 192 cycles at 133 MHz), giving 3 523 fps on the full 1280 × 864
    frame (seed: "up to 3 500 fps").

    When ``frame_overhead_cycles`` is None the overhead is the seed's 24 µs at the chosen
    clock (exactly 2 400 cycles at 100 MHz).
    """
    check_choice("mode", mode, ("reduced", "normal"))
    if pixel_clock_hz is None:
        pixel_clock_hz = 100e6 if mode == "reduced" else LUX13HS_NORMAL_CLOCK_HZ
    pixel_clock_hz = check_positive("pixel_clock_hz", pixel_clock_hz)
    if frame_overhead_cycles is None:
        frame_overhead_cycles = round(LUX13HS_FRAME_OVERHEAD_S * pixel_clock_hz)
    check_non_negative("frame_overhead_cycles", frame_overhead_cycles)
    return ReadoutTiming(pixel_clock_hz=pixel_clock_hz,
                         pixels_per_clock=4 if mode == "reduced" else 8,
                         frame_overhead_cycles=int(frame_overhead_cycles), mode=mode,
                         core_clock_divider=2 if mode == "reduced" else 1)


#: The seed's operating point: reduced mode, 100 MHz, 1280 × 720 window → 60 000 cycles.
SEED_ROI = Window((LUX13HS_HEIGHT - 720) // 2, 0, 720, 1280)
