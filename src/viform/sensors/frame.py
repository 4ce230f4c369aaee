"""The frame-sensor pixel model shared by every frame camera (timed exposure, seed 000 §2).

Signal chain per pixel, in the order of the EMVA 1288 linear camera model:

photons → ×η (QE) × (1 + PRNU) → Poisson shot noise (exact at any count) → + dark
electrons (Poisson, rate Id, plus a fixed DSNU offset) → clip at the full well → + read
noise (Gaussian, e⁻ rms) → × system gain K (DN/e⁻) → + black offset → ADC rounding and
clipping to [0, 2^bits − 1].

K follows from the conversion gain, the analog gain and the ADC input range when
``adc_range_v`` is given (K = CG · gain · (2^bits − 1) / V_range); otherwise the full well
maps to the ADC full scale above the black offset at unit analog gain.

Random numbers come from ``numpy.random.Generator(PCG64)`` seeded by
``SeedSequence([seed, frame_index])``, so frame k is the same whatever else is captured;
the fixed pattern (PRNU, DSNU) comes from ``fixed_pattern_seed`` and belongs to the sensor.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from viform._validate import (
    ViformError,
    check_int,
    check_non_negative,
    check_positive,
    check_range,
)
from viform.light.radiometry import PixelOptics, check_lux
from viform.light.scenes import Scene
from viform.sensors.base import FrameStack, Sensor


@dataclass(frozen=True)
class FramePixelParameters:
    """Parameters of a frame-sensor pixel and its readout (units in the names).

    Attributes
    ----------
    optics : PixelOptics
        Pitch, fill factor, quantum efficiency.
    full_well_electrons : float
        Charge the photodiode holds before it saturates, e⁻.
    conversion_gain_v_per_e : float
        Charge-to-voltage conversion at the sense node, V/e⁻.
    read_noise_electrons : float
        Temporal read noise, e⁻ rms (Gaussian: an electronic noise, not a count).
    dark_current_e_per_s : float
        Mean dark current, e⁻/s.
    dsnu_electrons : float
        Dark signal non-uniformity: std of a fixed per-pixel offset, e⁻.
    prnu_fraction : float
        Photo-response non-uniformity: std of the per-pixel relative gain.
    analog_gain : float
        Gain before the ADC (dimensionless).
    adc_bits : int
        ADC resolution, 1–16 bits.
    black_offset_dn : float
        Black level added before quantization, DN.
    adc_range_v : float or None
        ADC input range, V; None maps the full well to full scale.
    readout_time_s : float
        Time to read the array row by row after a global-shutter exposure, s: row r (of H)
        waits (r + 1)/H × this in its storage node. Default 0 (read at once: the storage
        effects below then do nothing).
    parasitic_light_sensitivity : float
        Fraction of the photodiode's photo-rate that still reaches the storage node while it
        holds the frame (1 − shutter efficiency; seed 002 Table 1: the LUX13HS's 99 % → 0.01).
        Light arriving during the wait adds PLS × rate × wait (Poisson). Default 0.
    storage_leakage_e_per_s : float
        Dark leakage into the storage node while it holds the frame, e⁻/s (Poisson). Default 0.
    black_sun_fraction : float
        Fraction β of the photo-rate that reaches the sense node between its reset and the
        reset sample of the correlated double sampling ("black sun", seed 001 §3.3 mentions it).
        Under extreme light the reset sample already holds n_r = β·rate·t_rs electrons, so the
        CDS output min(Q + n_r, FW) − min(n_r, FW) falls once Q + n_r passes the full well and
        reaches 0 (a black sun) when n_r ≥ FW. Default 0.
    reset_sample_time_s : float
        t_rs, the time from the sense node's reset to its reset sample, s. Default 1 µs (used
        only when ``black_sun_fraction`` > 0).
    """

    optics: PixelOptics = field(default_factory=lambda: PixelOptics(pixel_pitch_m=5.86e-6,
                                                                    quantum_efficiency=0.6))
    full_well_electrons: float = 20_000.0
    conversion_gain_v_per_e: float = 50e-6
    read_noise_electrons: float = 5.0
    dark_current_e_per_s: float = 50.0
    dsnu_electrons: float = 2.0
    prnu_fraction: float = 0.01
    analog_gain: float = 1.0
    adc_bits: int = 12
    black_offset_dn: float = 16.0
    adc_range_v: float | None = None
    readout_time_s: float = 0.0
    parasitic_light_sensitivity: float = 0.0
    storage_leakage_e_per_s: float = 0.0
    black_sun_fraction: float = 0.0
    reset_sample_time_s: float = 1e-6

    def __post_init__(self):
        check_positive("full_well_electrons", self.full_well_electrons)
        check_positive("conversion_gain_v_per_e", self.conversion_gain_v_per_e)
        check_non_negative("read_noise_electrons", self.read_noise_electrons)
        check_non_negative("dark_current_e_per_s", self.dark_current_e_per_s)
        check_non_negative("dsnu_electrons", self.dsnu_electrons)
        check_non_negative("prnu_fraction", self.prnu_fraction)
        check_positive("analog_gain", self.analog_gain)
        check_int("adc_bits", self.adc_bits, 1, 16)
        check_non_negative("black_offset_dn", self.black_offset_dn)
        if self.black_offset_dn >= self.max_dn:
            raise ViformError(f"black_offset_dn = {self.black_offset_dn!r} must be below the ADC "
                              f"full scale {self.max_dn} DN")
        if self.adc_range_v is not None:
            check_positive("adc_range_v", self.adc_range_v)
        check_non_negative("readout_time_s", self.readout_time_s)
        check_range("parasitic_light_sensitivity", self.parasitic_light_sensitivity, 0.0, 1.0)
        check_non_negative("storage_leakage_e_per_s", self.storage_leakage_e_per_s)
        check_range("black_sun_fraction", self.black_sun_fraction, 0.0, 1.0)
        check_non_negative("reset_sample_time_s", self.reset_sample_time_s)

    @property
    def shutter_efficiency(self) -> float:
        """1 − parasitic light sensitivity (seed 002 Table 1 quotes 99 % for the LUX13HS)."""
        return 1.0 - self.parasitic_light_sensitivity

    @property
    def max_dn(self) -> int:
        """Largest ADC code, 2^bits − 1."""
        return (1 << int(self.adc_bits)) - 1

    @property
    def system_gain_dn_per_e(self) -> float:
        """Overall system gain K, DN per electron."""
        if self.adc_range_v is not None:
            return self.conversion_gain_v_per_e * self.analog_gain * self.max_dn / self.adc_range_v
        return self.analog_gain * (self.max_dn - self.black_offset_dn) / self.full_well_electrons

    def to_dict(self) -> dict:
        d = asdict(self)
        d["system_gain_dn_per_e"] = self.system_gain_dn_per_e
        return d


class FramePixelArray:
    """A global-shutter array of :class:`FramePixelParameters` pixels with its fixed pattern.

    The building blocks (:meth:`mean_signal_electrons`, :meth:`collect_electrons`,
    :meth:`digitize`) are public so HDR pixel models can change what happens to the charge
    between collection and readout while keeping the same noise physics.
    """

    def __init__(self, parameters: FramePixelParameters, height: int, width: int,
                 fixed_pattern_seed: int = 1288):
        self.parameters = parameters
        self.height = check_int("height", height, 1)
        self.width = check_int("width", width, 1)
        self.fixed_pattern_seed = int(fixed_pattern_seed)
        fpn = np.random.Generator(np.random.PCG64(np.random.SeedSequence([self.fixed_pattern_seed, 0xF1])))
        # Gain can't go negative: clip the (rare) far tail of a wide PRNU.
        self.prnu_gain = np.clip(1.0 + parameters.prnu_fraction * fpn.standard_normal((height, width)),
                                 0.0, None)
        self.dsnu_offset_electrons = parameters.dsnu_electrons * fpn.standard_normal((height, width))

    @staticmethod
    def rng(seed: int, frame_index: int) -> np.random.Generator:
        """The generator for one frame: independent of how many frames are captured."""
        return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed), int(frame_index)])))

    def mean_signal_electrons(self, mean_lux, exposure_s: float) -> np.ndarray:
        """Expected photoelectrons (signal only, PRNU applied) for mean illuminance over the exposure."""
        check_non_negative("exposure_s", exposure_s)
        lux = check_lux(mean_lux, "mean_lux")
        return self.parameters.optics.electrons_per_s(lux) * exposure_s * self.prnu_gain

    def collect_electrons(self, mean_lux, exposure_s: float, rng: np.random.Generator,
                          noise: bool = True) -> np.ndarray:
        """Photo + dark electrons collected during ``exposure_s``, before the full-well clip (float64).

        Shot noise and dark-current noise are Poisson, exact at small counts.
        """
        signal = self.mean_signal_electrons(mean_lux, exposure_s)
        dark = self.parameters.dark_current_e_per_s * exposure_s
        if noise:
            return rng.poisson(signal + dark).astype(np.float64)
        return signal + dark

    def storage_wait_s(self) -> np.ndarray:
        """Time each row's charge waits in its storage node before it is read, (H, 1), s."""
        rows = np.arange(1, self.height + 1, dtype=np.float64)[:, None]
        return rows / self.height * self.parameters.readout_time_s

    def storage_electrons(self, scene: Scene, end_s: float, rng: np.random.Generator,
                          noise: bool = True, samples: int = 32) -> np.ndarray | float:
        """Charge a global shutter's storage nodes gather while they wait to be read (H, W).

        Row r waits w_r = (r + 1)/H · readout_time_s after the exposure ends at ``end_s``; it
        gathers PLS × the photo-rate of the light during [end_s, end_s + w_r] plus the storage
        leakage, both Poisson: mean = PLS·η·Φ(L̄_r)·w_r·(1 + PRNU) + leak·w_r, L̄_r the row's mean
        light over its wait (:meth:`storage_light_lux`, ``samples`` looks at the scene). Returns
        0.0 when the effects are off.
        """
        p = self.parameters
        if p.readout_time_s == 0 or (p.parasitic_light_sensitivity == 0 and p.storage_leakage_e_per_s == 0):
            return 0.0
        wait = self.storage_wait_s()
        mean = p.storage_leakage_e_per_s * wait * np.ones((self.height, self.width))
        if p.parasitic_light_sensitivity > 0:
            lux = self.storage_light_lux(scene, end_s, samples)
            mean = mean + p.parasitic_light_sensitivity * self.mean_signal_electrons(lux, 1.0) * wait
        return rng.poisson(mean).astype(np.float64) if noise else mean

    def storage_light_lux(self, scene: Scene, end_s: float, samples: int = 32) -> np.ndarray:
        """Each row's mean light over its wait [end_s, end_s + w_r], lux (H, W).

        The readout [end_s, end_s + T_read] is cut into M = min(H, ``samples``) equal segments,
        each averaged by the scene (its own integral where it has one, else the midpoint rule
        with ⌈samples/M⌉ points): ``samples`` light evaluations in all, not one per row. Row r's
        integral is the segments before w_r plus the share of the one it ends in (the light
        taken constant within a segment, T_read/M); with M = H every wait ends on a segment
        edge and the rows are exact. Written as S₀ + Σ_k (S_k − S₀)·Δ_k/w_r, so still light
        gives exactly its value.
        """
        samples = check_int("samples", samples, 1)
        height, width = self.height, self.width
        read_s = self.parameters.readout_time_s
        n_seg = min(height, samples)
        per_segment = -(-samples // n_seg)
        seg_s = read_s / n_seg
        # row r's wait in segment units: (r + 1)·M/H; it ends in segment ⌈·⌉ − 1
        ends = (np.arange(1, height + 1) * n_seg) / height
        last = np.minimum(np.ceil(ends - 1e-9).astype(np.int64) - 1, n_seg - 1)
        first_light = None
        acc = np.zeros((height, width))  # Σ_k (S_k − S₀)·(time of the row's wait in segment k)
        for k in range(n_seg):
            a = end_s + k * seg_s
            light = np.asarray(scene.mean_illuminance_lux(a, a + seg_s, samples=per_segment), dtype=np.float64)
            if first_light is None:
                first_light = light
                continue
            rows = last >= k
            if not rows.any():
                break
            span = np.clip(ends[rows] - k, 0.0, 1.0)[:, None] * seg_s  # the row's time in segment k
            acc[rows] += (light[rows] - first_light[rows]) * span
        wait = self.storage_wait_s()
        return first_light + acc / wait

    def black_sun_electrons(self, electrons, mean_lux) -> np.ndarray:
        """CDS output with the reset sample eaten by the light (black sun), e⁻.

        n_r = β·η·Φ(lux)·t_rs reaches the sense node before its reset sample; the signal sample
        holds Q + n_r, both clipped at the full well: output min(Q + n_r, FW) − min(n_r, FW).
        The light at the reset sample is taken as ``mean_lux`` (the exposure's mean light).
        """
        p = self.parameters
        fw = p.full_well_electrons
        q = np.minimum(np.asarray(electrons, dtype=np.float64), fw)
        n_r = p.black_sun_fraction * p.optics.electrons_per_s(check_lux(mean_lux, "mean_lux")) * p.reset_sample_time_s
        return np.minimum(q + n_r, fw) - np.minimum(n_r, fw)

    def digitize(self, electrons, rng: np.random.Generator, noise: bool = True) -> np.ndarray:
        """Full-well clip, DSNU, read noise, gain, black offset and ADC: electrons → DN (uint16)."""
        p = self.parameters
        charge = np.minimum(np.asarray(electrons, dtype=np.float64), p.full_well_electrons)
        charge = charge + self.dsnu_offset_electrons
        if noise and p.read_noise_electrons > 0:
            charge = charge + p.read_noise_electrons * rng.standard_normal(charge.shape)
        dn = np.rint(charge * p.system_gain_dn_per_e + p.black_offset_dn)
        return np.clip(dn, 0, p.max_dn).astype(np.uint16)


class FrameSensor(Sensor):
    """A conventional global-shutter frame camera with a timed exposure (seed 000 §2).

    Parameters
    ----------
    parameters : FramePixelParameters
    exposure_s : float
        Exposure time per frame, seconds.
    frame_rate_hz : float
        Frames per second; the exposure must fit in the frame period.
    height, width : int or None
        Resolution; None takes the scene's.
    noise : bool
        False gives the expected values (no shot, dark or read noise; fixed pattern kept).
    fixed_pattern_seed : int
        Seed of the sensor's own PRNU/DSNU pattern.
    """

    name = "frame"

    def __init__(self, parameters: FramePixelParameters | None = None, exposure_s: float = 10e-3,
                 frame_rate_hz: float = 30.0, height: int | None = None, width: int | None = None,
                 noise: bool = True, fixed_pattern_seed: int = 1288):
        self.parameters = parameters or FramePixelParameters()
        self.exposure_s = check_positive("exposure_s", exposure_s)
        self.frame_rate_hz = check_positive("frame_rate_hz", frame_rate_hz)
        if self.exposure_s > 1.0 / self.frame_rate_hz * (1 + 1e-12):
            raise ViformError(f"exposure_s = {exposure_s!r} exceeds the frame period "
                              f"{1.0 / self.frame_rate_hz:g} s at frame_rate_hz = {frame_rate_hz!r}")
        self.height, self.width = height, width
        self.noise = bool(noise)
        self.fixed_pattern_seed = int(fixed_pattern_seed)
        self._arrays: dict[tuple[int, int], FramePixelArray] = {}

    def pixel_array(self, height: int, width: int) -> FramePixelArray:
        """The sensor's pixel array (with its fixed pattern) at this resolution."""
        key = (height, width)
        if key not in self._arrays:
            self._arrays[key] = FramePixelArray(self.parameters, height, width, self.fixed_pattern_seed)
        return self._arrays[key]

    def capture_frame(self, scene: Scene, start_s: float, exposure_s: float, *, seed: int = 0,
                      frame_index: int = 0) -> np.ndarray:
        """One frame exposed over [start_s, start_s + exposure_s], in DN."""
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = self.pixel_array(height, width)
        rng = pixels.rng(seed, frame_index)
        lux = scene.mean_illuminance_lux(start_s, start_s + exposure_s)
        electrons = pixels.collect_electrons(lux, exposure_s, rng, self.noise)
        # global shutter: the frame waits in the storage nodes while rows are read
        electrons = electrons + pixels.storage_electrons(scene, start_s + exposure_s, rng, self.noise)
        if self.parameters.black_sun_fraction > 0:
            electrons = pixels.black_sun_electrons(electrons, lux)
        return pixels.digitize(electrons, rng, self.noise)

    def capture(self, scene: Scene, duration_s: float, *, seed: int = 0) -> FrameStack:
        """Frames at ``frame_rate_hz`` over ``duration_s`` (at least one frame)."""
        check_positive("duration_s", duration_s)
        n = max(1, int(np.floor(duration_s * self.frame_rate_hz + 1e-9)))
        starts = np.arange(n) / self.frame_rate_hz
        frames = np.stack([self.capture_frame(scene, float(t), self.exposure_s, seed=seed, frame_index=i)
                           for i, t in enumerate(starts)])
        return FrameStack(frames, starts, np.full(n, self.exposure_s),
                          {"sensor": self.describe(), "scene": scene.describe(), "seed": seed})

    def describe(self) -> dict:
        return {"model": self.name, "exposure_s": self.exposure_s, "frame_rate_hz": self.frame_rate_hz,
                "noise": self.noise, "fixed_pattern_seed": self.fixed_pattern_seed,
                **self.parameters.to_dict()}
