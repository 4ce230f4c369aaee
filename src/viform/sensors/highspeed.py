"""The LUX13HS-like high-frame-rate camera as a sensor: pixels, readout timing and auto-exposure (seed 002).

Its native output is 8-bit frames (the high 8 bits of the 10-bit code, seed 002 §2.1) with the
exposure each frame had: the auto-exposure loop (seed 002 §3.2.4, :mod:`viform.sensors.auto_exposure`)
sets frame k + 1 + latency's exposure from frame k's gray, so the exposures are part of what the
camera produces. What happens to the frames after the sensor — the DDR ring, N:1 sampling for the
link and histogram equalization — is the camera's processing chain
(:func:`viform.isp.highspeed_pipeline.run_highspeed`).

Timing, link and buffer follow the *readout window* (``roi``); the image itself may be rendered on
a coarser grid (the scene's resolution): each rendered pixel is one real pixel of the window, so its
noise is a real pixel's.
"""

from __future__ import annotations

import math
from dataclasses import asdict, replace

import numpy as np

from viform._validate import check_int, check_positive
from viform.light.radiometry import PixelOptics
from viform.light.scenes import Scene
from viform.sensors.auto_exposure import METERS, AutoExposure, make_meter
from viform.sensors.base import FrameStack, Sensor
from viform.sensors.frame import FramePixelParameters, FrameSensor
from viform.sensors.highspeed_timing import Window, lux13hs_timing


def lux13hs_pixel_parameters(**overrides) -> FramePixelParameters:
    """LUX13HS-like pixel (seed 002, Table 1).

    QE 45 % (at 550 nm), 13.7 µm pitch, full well 30 ke⁻, read noise 15 e⁻, conversion gain
    40 µV/e⁻, 10-bit column ADC. Mapping of the datasheet's relative figures:

    * PRNU 1.5 % rms → ``prnu_fraction = 0.015`` (relative gain spread, as defined);
    * DSNU 0.5 % rms → ``dsnu_electrons = 0.005 × 30 000 = 150 e⁻``: datasheets quote DSNU
      as a fraction of the saturation (full-swing) signal;
    * ADC input range = full well × conversion gain = 1.2 V, so K = 40 µV/e⁻ · 1023 / 1.2 V
      = 0.0341 DN/e⁻; black offset 8 DN (2 gray levels in 8 bit) so DSNU and read noise
      are not clipped at zero;
    * dark current 1 000 e⁻/s (not in the seed; negligible at sub-millisecond exposures);
    * shutter efficiency 99 % (Table 1, 快门效率) → ``parasitic_light_sensitivity = 0.01``: while a
      frame waits in the storage node SG to be read, 1 % of the photodiode's photo-rate still
      reaches it (:meth:`~viform.sensors.frame.FramePixelArray.storage_electrons`). The wait is
      the readout's, set by :class:`HighSpeedCamera` from its timing (``readout_time_s``).

    The datasheet's 25 V/(lux·s) responsivity is not imposed: our 555 nm monochromatic lux
    conversion gives 13.8 V/(lux·s) for this pixel (white light has more photons per lux).
    """
    base = dict(optics=PixelOptics(pixel_pitch_m=13.7e-6, fill_factor=1.0, quantum_efficiency=0.45),
                full_well_electrons=30_000.0, conversion_gain_v_per_e=40e-6,
                read_noise_electrons=15.0, dark_current_e_per_s=1_000.0,
                dsnu_electrons=0.005 * 30_000.0, prnu_fraction=0.015, analog_gain=1.0, adc_bits=10,
                black_offset_dn=8.0, adc_range_v=30_000.0 * 40e-6, parasitic_light_sensitivity=0.01)
    base.update(overrides)
    return FramePixelParameters(**base)


def to_gray8(frames_dn, adc_bits: int) -> np.ndarray:
    """The high 8 bits of an ``adc_bits`` code (seed 002 §2.1: the LUX13HS outputs the high 8
    and low 2 bits of its 10-bit code on separate channels; the 8-bit path keeps the high 8)."""
    adc_bits = check_int("adc_bits", adc_bits, 8, 16)
    return (np.asarray(frames_dn).astype(np.uint16) >> (adc_bits - 8)).astype(np.uint8)


class HighSpeedCamera(Sensor):
    """LUX13HS-like camera: global-shutter pixels read in ``roi`` at the sensor's clock, with auto-exposure.

    Parameters
    ----------
    parameters : FramePixelParameters
        The pixel (default :func:`lux13hs_pixel_parameters`). Its ``readout_time_s``, when 0 (the
        default), becomes the window's readout time at the clock
        (:meth:`~viform.sensors.highspeed_timing.ReadoutTiming.readout_time_s`): each row's charge
        waits its share of it in the storage node, under the shutter's parasitic light; a
        non-zero value is kept (a what-if).
    roi : str or Window
        Readout window on the 1280 × 864 array ("WxH" centred or "X,Y,W,H"); sets the frame rate.
    mode : {"reduced", "normal"}
        LUX13HS readout mode (4 or 8 pixels a clock).
    pixel_clock_hz : float or None
        Sensor clock, Hz (None: 100 MHz reduced, 133 MHz normal).
    ae : bool
        Auto-exposure on (else every frame keeps ``exposure_s``).
    meter : {"mean", "weighted", "percentile"}
        What the auto-exposure meters (:data:`~viform.sensors.auto_exposure.METERS`).
    target_gray, band_gray : float
        Target gray R_i (0–255) and half-width of the dead band, gray levels (seed: 128 ± 15).
    ae_latency_frames : int
        Frames between the metered frame and the first one with its new exposure (1: frame k + 1
        is already exposing while frame k is read out, seed 002 §3.2.4).
    ae_saturated_cut : float or None
        k of the optional saturation-aware step (A2) of :mod:`viform.sensors.auto_exposure`.
    exposure_s : float
        Initial exposure (fixed without AE), s; a whole number of clock periods.
    scene_samples : int
        Points of the midpoint rule for the light during one exposure, and looks at the light
        while the rows wait to be read (:meth:`~viform.sensors.frame.FramePixelArray.storage_light_lux`).
    """

    name = "highspeed"

    def __init__(self, parameters: FramePixelParameters | None = None, roi: str | Window = "1280x720",
                 mode: str = "reduced", pixel_clock_hz: float | None = None, ae: bool = True, meter: str = "mean",
                 target_gray: float = 128.0, band_gray: float = 15.0, ae_latency_frames: int = 1,
                 ae_saturated_cut: float | None = None, exposure_s: float = 100e-6, scene_samples: int = 4):
        self.parameters = parameters or lux13hs_pixel_parameters()
        check_int("adc_bits", self.parameters.adc_bits, 8, 16)  # the 8-bit output keeps the high 8 bits
        self.timing = lux13hs_timing(mode, pixel_clock_hz)
        self.mode = mode
        self.pixel_clock_hz = self.timing.pixel_clock_hz
        self.window = self.timing.window(roi)
        if self.parameters.readout_time_s == 0:
            self.parameters = replace(self.parameters, readout_time_s=self.timing.readout_time_s(self.window))
        self.roi = roi
        self.ae = bool(ae)
        self.meter = meter
        if meter not in METERS:
            make_meter(meter)  # the error names the meters
        self.target_gray = float(target_gray)
        self.band_gray = float(band_gray)
        self.ae_latency_frames = check_int("ae_latency_frames", ae_latency_frames, 0, 8)
        self.ae_saturated_cut = ae_saturated_cut
        self.exposure_s = check_positive("exposure_s", exposure_s)
        self.initial_exposure_cycles = self.timing.exposure_cycles(self.exposure_s, self.window)
        self.scene_samples = check_int("scene_samples", scene_samples, 1)
        self._controller()  # target, band and cut checked now, not at the first frame

    @property
    def frame_period_s(self) -> float:
        """Time from one frame to the next, s (the readout of the window at the clock)."""
        return self.timing.frame_period_s(self.window)

    @property
    def frame_rate_hz(self) -> float:
        return self.timing.frame_rate_hz(self.window)

    def frames_in(self, duration_s: float) -> int:
        """Frames that end inside ``duration_s`` (at least one)."""
        return max(1, int(math.floor(check_positive("duration_s", duration_s) / self.frame_period_s + 1e-9)))

    def _controller(self) -> AutoExposure:
        p = self.parameters
        black_gray = p.black_offset_dn / (1 << (p.adc_bits - 8))
        return AutoExposure(self.timing.max_exposure_cycles(self.window), self.target_gray, self.band_gray,
                            make_meter(self.meter), black_level_gray=black_gray,
                            saturated_cut=self.ae_saturated_cut)

    def capture(self, scene: Scene, duration_s: float, *, seed: int = 0) -> FrameStack:
        """8-bit frames over ``duration_s`` (every frame that ends inside it) with their exposures."""
        return self.capture_frames(scene, self.frames_in(duration_s), seed=seed)

    def capture_frames(self, scene: Scene, n_frames: int, *, seed: int = 0, progress=None) -> FrameStack:
        """``n_frames`` consecutive frames from t = 0; ``progress(1)`` is called after each.

        Frame k ends at (k + 1)·T_frame (the frame transfer) and exposes for its N_k clock
        periods before that; ``metadata`` holds N_k (``exposure_cycles``), what the meter saw
        (``metered_gray``) and each frame's end (``frame_end_s``).
        """
        n = check_int("n_frames", n_frames, 1)
        timing, p = self.timing, self.parameters
        period_s = self.frame_period_s
        pixels = FrameSensor(p, exposure_s=period_s * 0.5, frame_rate_hz=self.frame_rate_hz).pixel_array(
            scene.height, scene.width)
        controller = self._controller()
        latency = self.ae_latency_frames
        n_cycles = self.initial_exposure_cycles
        gray = np.empty((n, scene.height, scene.width), dtype=np.uint8)
        cycles = np.empty(n, dtype=np.int64)
        metered = np.empty(n)
        ends = (np.arange(n) + 1) * period_s
        scheduled: dict[int, int] = {}
        command = n_cycles  # the latest exposure sent to the sensor
        for k in range(n):
            cycles[k] = scheduled.pop(k, n_cycles)
            n_cycles = int(cycles[k])
            t_exp = n_cycles * timing.clock_period_s
            lux = scene.mean_illuminance_lux(ends[k] - t_exp, ends[k], samples=self.scene_samples)
            rng = pixels.rng(seed, k)
            electrons = pixels.collect_electrons(lux, t_exp, rng)
            # global shutter: the frame waits in the storage nodes while the rows are read, under
            # parasitic light (0 when readout_time_s or both parasitic light and storage leakage are 0)
            electrons = electrons + pixels.storage_electrons(scene, float(ends[k]), rng, samples=self.scene_samples)
            if p.black_sun_fraction > 0:
                electrons = pixels.black_sun_electrons(electrons, lux)
            dn = pixels.digitize(electrons, rng)
            gray[k] = to_gray8(dn, p.adc_bits)
            metered[k], nxt = controller.update(gray[k], n_cycles)
            if self.ae:
                # Frames k+1 … k+latency already have their exposure; the new N starts after them.
                for j in range(k + 1, k + 1 + latency):
                    scheduled.setdefault(j, n_cycles)
                # A frame exposed with a superseded N (the command was sent while it was
                # already exposing) is not fed back: otherwise two interleaved loops form.
                if n_cycles != command:
                    nxt = command
                scheduled[k + 1 + latency] = command = nxt
            if progress is not None:
                progress(1)
        exposure_s = cycles * timing.clock_period_s
        return FrameStack(gray, ends - exposure_s, exposure_s,
                          {"sensor": self.describe(), "scene": scene.describe(), "seed": seed,
                           "exposure_cycles": cycles, "metered_gray": metered, "frame_end_s": ends,
                           "units": "8-bit gray: the high 8 bits of the 10-bit code (DN >> 2)"})

    def describe(self) -> dict:
        return {"model": self.name, "roi": asdict(self.window), "mode": self.mode,
                "pixel_clock_hz": self.pixel_clock_hz, "frame_rate_hz": self.frame_rate_hz,
                "ae": self.ae, "meter": self.meter, "target_gray": self.target_gray, "band_gray": self.band_gray,
                "ae_latency_frames": self.ae_latency_frames, "ae_saturated_cut": self.ae_saturated_cut,
                "exposure_s": self.exposure_s, "scene_samples": self.scene_samples,
                "timing": self.timing.summary(self.window), "pixel": self.parameters.to_dict()}
