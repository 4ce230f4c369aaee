"""Range gating with an interline-transfer CCD, no image intensifier (seed 004).

Seed 004, "Control in an undocumented way": instead of one readout pulse per frame, each
laser pulse is followed, 2R/c later, by the end of the SUB (substrate) erase pulse; the
photodiodes integrate for t_нак and the V2/V3 readout pulse moves their charge into the
vertical CCD (the shielded buffer register). Because the buffer is isolated from the
photodiodes, the next SUB erases only the photodiodes, and the next transfer *adds* its
charge to what the buffer already holds. After X pulses the frame is read out once, so
read noise and ADC quantization are paid once per frame (seed 004, Fig. 3;
t_экспозиции = X·t_нак).

Gate timing (seed 004, Fig. 3):

* delay t_откл = 2R/c, R the gate's near range (the "minimum illumination distance");
* t_нак = τ_pulse + t_min, t_min the sensor's minimum time between the SUB falling edge
  and the V2/V3 transfer pulse (a datasheet figure; 1 µs assumed for the ICX618 here);
* the V2/V3 readout pulse (t_read, assumed 1 µs) follows; the photodiodes keep passing
  charge to the register while it is high, so light counts from SUB's fall to the pulse's
  end, t_нак + t_read (:class:`GateTiming`; the drawn waveforms use the same instants);
* a return from range r lasts [2r/c, 2r/c + τ]; it is (partly) recorded for
  R − cτ/2 < r < R + c·(t_нак + t_read)/2.

Three ways of using X pulses are compared (seed 004, "Requirements"):

``"ungated"``
    The documented shutter: SUB ends 2R/c after the first pulse and the photodiodes then
    integrate until the single transfer after the X-th pulse. Only the first return is
    gated; the other X − 1 bring everything back, fog included, plus ambient light for
    the whole (X − 1)/f_rep.
``"sum"``
    One gated pulse per frame, X frames each read out and digitized, summed digitally: read
    noise and quantization X times, and the frame rate divided by X.
``"accumulate"``
    The seed's method: X gated exposures summed in the vertical register, one readout.

Noise chain (reuses :class:`viform.sensors.frame.FramePixelArray`): Poisson photo, ambient
and dark electrons (the sum of X independent Poisson counts is Poisson with the summed
mean, so a frame's count is drawn at once — exact, not an approximation), PRNU on the
photo-signal, then ``FramePixelArray.digitize`` (full-well clip, DSNU, Gaussian read
noise, gain, offset, ADC) once per readout.

The shutter is not perfect: a fraction ``shutter_leak_ratio`` of the light arriving while
SUB holds the photodiodes empty still reaches the buffer (the smear path; ICX-series smear
is ≈ −100 dB). This is what lets a very strong close reflector leave a trace.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
)
from viform.light.active import ActiveImagingGeometry, ActiveScene
from viform.light.laser import PulsedLaser, Receiver
from viform.light.radiometry import PixelOptics
from viform.sensors.base import FrameStack, Sensor
from viform.sensors.frame import FramePixelArray, FramePixelParameters
from viform.sensors.gate_timing import GateTiming
from viform.sensors.gated_waveforms import DRIVES, drive_waveforms

MODES = ("ungated", "sum", "accumulate")


def icx618_pixel_parameters() -> FramePixelParameters:
    """ICX618ALA-like pixel and readout (assumed values, seed 004 names only the part).

    1/4-type progressive interline CCD, 659 × 494 effective pixels of 5.6 µm; QE at 905 nm
    ≈ 0.25 (EXview HAD NIR response ≈ 40 % of a ≈ 60 % peak); 12 000 e⁻ full well; 12 e⁻
    read noise through a 12-bit CCD AFE; 64 DN black level.
    """
    return FramePixelParameters(
        optics=PixelOptics(pixel_pitch_m=5.6e-6, fill_factor=1.0, quantum_efficiency=0.25, wavelength_m=905e-9),
        full_well_electrons=12_000.0,
        conversion_gain_v_per_e=40e-6,
        read_noise_electrons=12.0,
        dark_current_e_per_s=20.0,
        dsnu_electrons=2.0,
        prnu_fraction=0.01,
        analog_gain=1.0,
        adc_bits=12,
        black_offset_dn=64.0,
    )


@dataclass(frozen=True)
class InterlineCCDParameters:
    """An interline-transfer CCD used as a gated receiver.

    Attributes
    ----------
    pixel : FramePixelParameters
        Pixel and readout chain (optics.quantum_efficiency is the QE at the laser line).
    sensor_height_px, sensor_width_px : int
        Full format (ICX618: 494 × 659).
    min_transfer_time_s : float
        Shortest SUB-fall → V2/V3 transfer interval, s (seed: t_нак = pulse + this).
    readout_pulse_s : float
        Width of the +15 V V2/V3 readout pulse, s (assumed 1 µs; Sony ICX parts 1–3 µs). The
        photodiodes keep collecting while it is high (see :class:`GateTiming`).
    readout_time_s : float
        Time to shift the whole frame out, s (ICX618: 60 frames/s progressive → 1/60 s).
    shutter_leak_ratio : float
        Fraction of the light arriving outside the gate that still reaches the buffer (the
        smear ratio: light reaching the vertical register relative to the photodiode).
    gate_jitter_s : float
        Rms timing jitter between the laser pulse and the drive edges (Gaussian; SUB and the
        transfer pulse move together), s. The expected gate is the nominal one averaged over
        the jitter. Default 0 (typical trigger jitter of an FPGA-timed diode laser: 1–5 ns).
    sub_fall_time_s : float
        Duration of SUB's falling edge, s: the photodiodes start collecting progressively, as
        a linear ramp centred on ``open_s`` (equivalently, the opening instant averaged
        uniformly over the edge). Default 0 (ideal edge; typical 20–100 ns for a +20 V swing).
    laser_rise_time_s : float
        Rise (= fall) time of the laser pulse, s: the pulse becomes a trapezoid of the same
        energy and FWHM τ, i.e. the rectangle convolved with a t_r-wide box, which is the same as
        averaging both gate edges uniformly over ±t_r/2. Default 0 (rectangle; typical 5–20 ns
        for a pulsed laser diode).
    transfer_smear : bool
        Add the smear of the vertical transfer: each packet crosses the rows between it and the
        horizontal register, one line time each, and gathers ``shutter_leak_ratio`` × their
        light (ambient; the laser is off during readout): a vertical streak under bright
        ambient light (sunlit surfaces, the sun). Default False.
    bloom : bool
        Charge above ``register_capacity_electrons`` in a vertical-register packet spills into
        its neighbours along the column (half up, half down) until every packet fits: a
        blooming streak. Default False (the excess is clipped, as by the readout).
    register_capacity_electrons : float or None
        Vertical-register packet capacity, e⁻ (default: the pixel's full well).
    interlaced : bool
        An interlaced part (ICX279, ICX659) read in field-integration mode: each output row is
        the sum of two adjacent photodiode rows (the readout pulse on V1 and V3 puts both into
        one field), so the output has half the rows and twice the signal per row. Default False.
    part : str
        The drive this CCD takes (:data:`viform.sensors.gated_waveforms.DRIVES`): which phases
        carry the readout pulse, extra signals; :func:`interline_ccd_parameters` builds a part's
        CCD with its format, interlacing and field time.
    """

    pixel: FramePixelParameters = field(default_factory=icx618_pixel_parameters)
    sensor_height_px: int = 494
    sensor_width_px: int = 659
    min_transfer_time_s: float = 1.0e-6
    readout_pulse_s: float = 1.0e-6
    readout_time_s: float = 1.0 / 60.0
    shutter_leak_ratio: float = 1e-5
    gate_jitter_s: float = 0.0
    sub_fall_time_s: float = 0.0
    laser_rise_time_s: float = 0.0
    transfer_smear: bool = False
    bloom: bool = False
    register_capacity_electrons: float | None = None
    interlaced: bool = False
    part: str = "icx618"

    def __post_init__(self):
        check_int("sensor_height_px", self.sensor_height_px, 1)
        check_int("sensor_width_px", self.sensor_width_px, 1)
        check_positive("min_transfer_time_s", self.min_transfer_time_s)
        check_positive("readout_pulse_s", self.readout_pulse_s)
        check_positive("readout_time_s", self.readout_time_s)
        check_non_negative("shutter_leak_ratio", self.shutter_leak_ratio)
        if self.shutter_leak_ratio > 1:
            raise ViformError(f"shutter_leak_ratio = {self.shutter_leak_ratio!r} must be ≤ 1")
        check_non_negative("gate_jitter_s", self.gate_jitter_s)
        check_non_negative("sub_fall_time_s", self.sub_fall_time_s)
        check_non_negative("laser_rise_time_s", self.laser_rise_time_s)
        if self.register_capacity_electrons is not None:
            check_positive("register_capacity_electrons", self.register_capacity_electrons)
        check_choice("part", self.part, ("icx618", "icx445", "icx279", "icx659"))

    @property
    def capacity_electrons(self) -> float:
        """Vertical-register packet capacity, e⁻."""
        return (self.pixel.full_well_electrons if self.register_capacity_electrons is None
                else float(self.register_capacity_electrons))


def interline_ccd_parameters(part: str = "icx618", **overrides) -> InterlineCCDParameters:
    """The CCD of one of seed 004's parts, as a sensor model (not only a drive).

    Format, interlacing, readout-pulse width, t_min and field (frame) readout time come from the
    part's drive (:data:`viform.sensors.gated_waveforms.DRIVES`): the interlaced ICX279 (PAL,
    2 × 291 lines, 64 µs per line) and ICX659 (2 × 247 lines, 63.5 µs) read one field of summed
    row pairs; the ICX445 runs its 1280 × 600 centre window. The pixel (QE, full well, noise) is
    the ICX618-like one of :func:`icx618_pixel_parameters` for every part (assumed: the seed gives
    no pixel data), so the parts differ here in format, field integration and timing only.
    """
    key = check_choice("part", str(part).lower(), tuple(DRIVES))
    d = DRIVES[key]
    kw = dict(part=key, interlaced=d.interlaced, sensor_height_px=d.rows * (2 if d.interlaced else 1),
              sensor_width_px=d.cols, min_transfer_time_s=d.min_transfer_time_s, readout_pulse_s=d.readout_pulse_s,
              readout_time_s=d.rows * d.line_time_s)
    kw.update(overrides)
    return InterlineCCDParameters(**kw)


@dataclass
class GatedFrame:
    """One output frame of a gated camera.

    Attributes
    ----------
    dn : ndarray (H, W) float64
        The frame in DN (for ``"sum"`` the digital sum of X frames).
    black_dn : float
        Black level contained in ``dn`` (offset × number of readouts).
    system_gain_dn_per_e : float
    mean_electrons : ndarray (H, W)
        Expected electrons (before noise), for reference.
    mode : str
    pulses : int
    frame_time_s : float
    readouts : int
    """

    dn: np.ndarray
    black_dn: float
    system_gain_dn_per_e: float
    mean_electrons: np.ndarray
    mode: str
    pulses: int
    frame_time_s: float
    readouts: int

    @property
    def electrons(self) -> np.ndarray:
        """Black-subtracted frame converted back to electrons."""
        return (self.dn - self.black_dn) / self.system_gain_dn_per_e


class GatedInterlineCCD(Sensor):
    """ICX618-like interline CCD driven as a range-gated receiver (seed 004).

    Parameters
    ----------
    pulses : int
        X, laser pulses per output frame.
    gate_range_m : float
        Near edge of the gate, m (delay 2R/c).
    mode : {"accumulate", "sum", "ungated"}
    frame_rate_hz : float
        Required output frame rate; X must fit (X/f_rep + readout ≤ 1/frame_rate).
    geometry : ActiveImagingGeometry or None
        Laser, receiver, pixel pitch and QE; built from ``laser``/``receiver`` and the CCD if None.
    noise : bool
        False returns expected values through the same digitizer without random noise.
    """

    name = "gated-interline-ccd"

    def __init__(
        self,
        pulses: int = 20,
        gate_range_m: float = 150.0,
        mode: str = "accumulate",
        frame_rate_hz: float = 25.0,
        parameters: InterlineCCDParameters | None = None,
        laser: PulsedLaser | None = None,
        receiver: Receiver | None = None,
        noise: bool = True,
        fixed_pattern_seed: int = 618,
    ):
        self.parameters = parameters or InterlineCCDParameters()
        self.laser = laser or PulsedLaser()
        self.receiver = receiver or Receiver()
        self.mode = check_choice("mode", mode, MODES)
        self.pulses = check_int("pulses", pulses, 1)
        self.frame_rate_hz = check_positive("frame_rate_hz", frame_rate_hz)
        self.timing = GateTiming(gate_range_m, self.laser, self.parameters.min_transfer_time_s,
                                 self.parameters.readout_pulse_s)
        px = self.parameters.pixel
        self.geometry = ActiveImagingGeometry(
            self.laser,
            self.receiver,
            px.optics.pixel_pitch_m,
            px.optics.quantum_efficiency * px.optics.fill_factor,
            self.parameters.sensor_height_px,
            self.parameters.sensor_width_px,
        )
        self.noise = bool(noise)
        self.fixed_pattern_seed = int(fixed_pattern_seed)
        limit = self.max_pulses(self.frame_rate_hz, self.mode)
        if self.pulses > limit:
            raise ViformError(
                f"pulses = {self.pulses} does not fit in a frame at frame_rate_hz = {frame_rate_hz:g}: "
                f"{self.mode} mode allows at most {limit} pulses (frame time "
                f"{self.frame_time_s(self.pulses) * 1e3:.1f} ms > {1e3 / self.frame_rate_hz:.1f} ms; "
                f"f_rep = {self.laser.repetition_hz:g} Hz, readout {self.parameters.readout_time_s * 1e3:.1f} ms)"
            )
        self._arrays: dict[tuple[int, int], FramePixelArray] = {}

    # ------------------------------------------------------------------ timing
    def frame_time_s(self, pulses: int | None = None, mode: str | None = None) -> float:
        """Time for one output frame: X pulse periods + readout(s)."""
        x = self.pulses if pulses is None else pulses
        mode = mode or self.mode
        t_read = self.parameters.readout_time_s
        if mode == "sum":  # every pulse needs its own full readout
            return x * max(t_read, self.laser.period_s)
        return x * self.laser.period_s + t_read

    def max_pulses(self, frame_rate_hz: float, mode: str | None = None) -> int:
        """Largest X whose frame fits in 1/frame_rate_hz."""
        mode = mode or self.mode
        period = 1.0 / frame_rate_hz
        t_read = self.parameters.readout_time_s
        if mode == "sum":
            return int(math.floor(period / max(t_read, self.laser.period_s) + 1e-9))
        return max(0, int(math.floor((period - t_read) * self.laser.repetition_hz + 1e-9)))

    def drive_waveforms(self, part: str | None = None, pulses: int | None = None, lines: int | None = None):
        """The drive (laser, SUB, V1–V4) of this sensor's gate, drawn from the same
        :class:`GateTiming` the physics uses (:func:`~viform.sensors.gated_waveforms.drive_waveforms`);
        ``part`` defaults to the CCD's own."""
        return drive_waveforms(part or self.parameters.part, pulses=self.pulses if pulses is None else pulses,
                               lines=lines, timing=self.timing)

    # ------------------------------------------------------------------ physics
    def pixel_array(self, height: int, width: int) -> FramePixelArray:
        key = (height, width)
        if key not in self._arrays:
            self._arrays[key] = FramePixelArray(self.parameters.pixel, height, width, self.fixed_pattern_seed)
        return self._arrays[key]

    def per_pulse_electrons(self, scene: ActiveScene) -> dict:
        """Expected electrons of one pulse: ``gated`` and ``all`` laser parts (dicts by source) and
        the ambient rate ``ambient_per_s`` (e⁻/s); independent of X and of the mode."""
        g = self.geometry
        return {
            "gated": self.gated_laser_electrons(scene),
            "all": g.laser_electrons(scene),
            "ambient_per_s": g.ambient_electrons_per_s(scene),
        }

    def gate_edge_offsets_s(self, jitter_nodes: int = 48, ramp_nodes: int = 8) -> list[tuple[float, float]]:
        """(opening shift, common shift) pairs of equal weight that sample the real edges: the
        SUB ramp (uniform over ±t_f/2, opening only), the jitter (Gaussian, both edges) and the
        laser pulse's rise (uniform over ±t_r/2, both edges), by their quantile midpoints."""
        from scipy.stats import norm

        par = self.parameters
        jit = ([par.gate_jitter_s * float(norm.ppf((i + 0.5) / jitter_nodes)) for i in range(jitter_nodes)]
               if par.gate_jitter_s > 0 else [0.0])
        ramp = ([par.sub_fall_time_s * ((j + 0.5) / ramp_nodes - 0.5) for j in range(ramp_nodes)]
                if par.sub_fall_time_s > 0 else [0.0])
        # a trapezoidal pulse = the rectangle smoothed by a t_r box: both edges shift uniformly
        rise = ([par.laser_rise_time_s * ((j + 0.5) / ramp_nodes - 0.5) for j in range(ramp_nodes)]
                if par.laser_rise_time_s > 0 else [0.0])
        return [(u, d + w) for u in ramp for d in jit for w in rise]

    def gated_laser_electrons(self, scene: ActiveScene) -> dict:
        """Laser electrons of one pulse inside the real gate (edges from :meth:`gate_edge_offsets_s`)."""
        g, t = self.geometry, self.timing
        offsets = self.gate_edge_offsets_s()
        if len(offsets) == 1:
            return g.laser_electrons(scene, t.open_s, t.close_s)
        parts = [g.laser_electrons(scene, t.open_s + u + d, t.close_s + d) for u, d in offsets]
        return {k: sum(p[k] for p in parts) / len(parts) for k in parts[0]}

    def transfer_smear_electrons(self, scene: ActiveScene, ambient_per_s=None) -> np.ndarray:
        """Smear of one vertical transfer, e⁻ (H, W): packet r crosses rows 0 … r − 1 (row 0 next
        to the horizontal register) for one line time each, gathering s × their ambient rate:
        s·t_line·Σ_{j<r} A_j, with t_line = readout_time_s / sensor_height_px."""
        par = self.parameters
        amb = self.geometry.ambient_electrons_per_s(scene) if ambient_per_s is None else ambient_per_s
        amb = np.broadcast_to(np.asarray(amb, dtype=np.float64), scene.shape)
        t_line = par.readout_time_s / par.sensor_height_px
        above = np.cumsum(amb, axis=0) - amb
        return par.shutter_leak_ratio * t_line * above

    def electron_budget(
        self, scene: ActiveScene, per_pulse: dict | None = None, pulses: int | None = None, mode: str | None = None
    ) -> dict:
        """Expected electrons per frame for X pulses in a mode (no noise, no PRNU).

        Keys: ``photo`` (per frame), ``dark`` (per frame), ``readouts``, ``per_readout_photo``,
        ``per_readout_dark``, ``per_pulse`` (see :meth:`per_pulse_electrons`).
        """
        pp = per_pulse or self.per_pulse_electrons(scene)
        x = self.pulses if pulses is None else check_int("pulses", pulses, 1)
        mode = mode or self.mode
        t = self.timing
        gated, all_, amb = pp["gated"]["total"], pp["all"]["total"], pp["ambient_per_s"]
        dark_rate = self.parameters.pixel.dark_current_e_per_s
        leak = self.parameters.shutter_leak_ratio
        period = self.laser.period_s
        if mode == "accumulate":
            outside = (all_ - gated) + amb * (period - t.width_s)
            photo = x * (gated + amb * t.width_s + leak * outside)
            dark = dark_rate * x * period  # photodiode + vertical register while charge is held
            readouts = 1
        elif mode == "sum":
            photo = x * (gated + amb * t.width_s)
            dark = dark_rate * x * t.width_s
            readouts = x
        else:  # ungated: SUB before pulse 1 only, single transfer after pulse X
            exposure = t.width_s + (x - 1) * period
            # pulse 1 is gated; pulses 2..X return whole (fog and close objects included)
            photo = gated + (x - 1) * all_ + amb * exposure
            dark = dark_rate * exposure
            readouts = 1
        if self.parameters.transfer_smear:  # every readout shifts the register out once
            photo = photo + readouts * self.transfer_smear_electrons(scene, amb)
        return {
            "per_pulse": pp,
            "photo": photo,
            "dark": dark,
            "readouts": readouts,
            "per_readout_photo": photo / readouts,
            "per_readout_dark": dark / readouts,
            "pulses": x,
            "mode": mode,
        }

    def capture_frame(
        self, scene: ActiveScene, *, seed: int = 0, frame_index: int = 0, budget: dict | None = None
    ) -> GatedFrame:
        """One output frame of ``scene`` in this sensor's mode."""
        h, w = scene.shape
        pixels = self.pixel_array(h, w)
        p = self.parameters.pixel
        b = budget or self.electron_budget(scene)
        rng = pixels.rng(seed, frame_index)
        mean_per_readout = b["per_readout_photo"] * pixels.prnu_gain + b["per_readout_dark"]
        par = self.parameters
        out_h = h // 2 if par.interlaced else h
        total = np.zeros((out_h, w))
        for _ in range(b["readouts"]):
            e = rng.poisson(mean_per_readout).astype(np.float64) if self.noise else mean_per_readout
            if par.interlaced:  # field integration: rows 2k and 2k + 1 share one register packet
                e = e[: 2 * out_h: 2] + e[1: 2 * out_h: 2]
            if par.bloom:
                e = bloom_columns(e, par.capacity_electrons)
            else:
                e = np.minimum(e, par.capacity_electrons)
            total += self.pixel_array(out_h, w).digitize(e, rng, self.noise)
        return GatedFrame(
            dn=total,
            black_dn=p.black_offset_dn * b["readouts"],
            system_gain_dn_per_e=p.system_gain_dn_per_e,
            mean_electrons=b["photo"] + b["dark"],  # per photodiode (before field summing)
            mode=b["mode"],
            pulses=b["pulses"],
            frame_time_s=self.frame_time_s(b["pulses"], b["mode"]),
            readouts=b["readouts"],
        )

    def expected_frame_stats(
        self, scene: ActiveScene | None = None, budget: dict | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Expected black-subtracted signal and temporal noise variance per pixel, in electrons.

        var = Poisson mean + readouts × (σ_read² + 1/(12 K²)); full-well clipping applied to
        the mean. The spatial fixed pattern (DSNU, PRNU) is added by the CNR code.
        """
        if budget is None and scene is None:
            raise ViformError("expected_frame_stats needs a scene or a budget")
        if self.parameters.interlaced or self.parameters.bloom:
            raise ViformError("expected_frame_stats gives per-photodiode statistics of a progressive part "
                              "without blooming; simulate frames (capture_frame) for interlaced=True or bloom=True")
        b = budget or self.electron_budget(scene)
        p = self.parameters.pixel
        n = b["readouts"]
        per = np.minimum(b["per_readout_photo"] + b["per_readout_dark"], p.full_well_electrons)
        mean = n * per
        k = p.system_gain_dn_per_e
        var = n * per * (per < p.full_well_electrons) + n * (p.read_noise_electrons**2 + 1.0 / (12 * k * k))
        return mean, var

    def capture(self, scene, duration_s: float, *, seed: int = 0) -> FrameStack:
        """Frames at ``frame_rate_hz`` over ``duration_s`` (scene static), DN as float64.

        ``scene`` is an :class:`ActiveScene` or a scene that carries one as ``scene.active`` (the
        laser-lit scene with ranges, e.g. the built-in night-road-fog). ``metadata["readouts"]``
        is the number of readouts summed in each frame (its black level is that many offsets).
        """
        check_positive("duration_s", duration_s)
        scene = active_scene(scene)
        n = max(1, int(math.floor(duration_s * self.frame_rate_hz + 1e-9)))
        b = self.electron_budget(scene)
        frames = np.stack([self.capture_frame(scene, seed=seed, frame_index=i, budget=b).dn for i in range(n)])
        return FrameStack(
            frames,
            np.arange(n) / self.frame_rate_hz,
            np.full(n, self.pulses * self.timing.width_s),
            {"sensor": self.describe(), "scene": scene.describe(), "seed": seed, "readouts": b["readouts"]},
        )

    def describe(self) -> dict:
        par = self.parameters
        extra = {k: getattr(par, k) for k in ("part", "readout_pulse_s", "gate_jitter_s", "sub_fall_time_s",
                                               "laser_rise_time_s", "transfer_smear", "bloom",
                                               "register_capacity_electrons", "interlaced")}
        return {
            "model": self.name,
            "mode": self.mode,
            "pulses": self.pulses,
            "frame_rate_hz": self.frame_rate_hz,
            "frame_time_s": self.frame_time_s(),
            "max_pulses_at_frame_rate": self.max_pulses(self.frame_rate_hz),
            "gate": self.timing.to_dict(),
            "geometry": self.geometry.to_dict(),
            "min_transfer_time_s": par.min_transfer_time_s,
            "readout_time_s": par.readout_time_s,
            "shutter_leak_ratio": par.shutter_leak_ratio,
            **extra,
            "noise": self.noise,
            "pixel": par.pixel.to_dict(),
        }


def active_scene(scene) -> ActiveScene:
    """The laser-lit scene with ranges that a gated camera shoots: ``scene`` itself or ``scene.active``."""
    if isinstance(scene, ActiveScene):
        return scene
    active = getattr(scene, "active", None)
    if active is None:
        raise ViformError("the scene has no range (the gated camera needs a laser-lit scene with distances, "
                          "e.g. night-road-fog)")
    return active


def bloom_columns(electrons, capacity_electrons: float) -> np.ndarray:
    """Spill charge above ``capacity_electrons`` along each column (axis 0): each overfilled
    packet, in turn, keeps C and sends half its excess up and half down the column, each half
    filling the free room of the packets it meets; what reaches a column's end is lost (drained
    by the horizontal register / the dump). Charge is conserved otherwise, so a packet of
    Q ≫ C becomes a streak of ≈ Q/C full packets centred on it (a blooming streak)."""
    e = np.array(electrons, dtype=np.float64)
    cap = float(capacity_electrons)
    n = e.shape[0]
    for c in np.flatnonzero((e > cap).any(axis=0)):
        col = e[:, c]  # a view: filled in place
        for i in np.flatnonzero(col > cap):
            excess = col[i] - cap
            if excess <= 0:
                continue
            col[i] = cap
            for step in (-1, 1):
                rest, j = excess / 2, i + step
                while rest > 0 and 0 <= j < n:
                    take = min(max(cap - col[j], 0.0), rest)
                    col[j] += take
                    rest -= take
                    j += step
    return e
