"""Medium-free light communication through a spike camera (seed 000 §7, last paragraph).

Seed 000 §7: "把脉冲连续显示作为可见光信号源，通过脉冲连续摄影进行高速采集，对超高速无介质光通信
意义重大" — a spike display (or any fast light source) used as a visible-light transmitter and
a spike camera as the receiver. This module simulates the whole link in physical units:

Transmitter
    An LED of on-axis luminous intensity ``I_v`` (cd) and emitting diameter ``D_led`` (m),
    switched between the on level and ``extinction_ratio``·on by a bit stream, with on-off
    keying (OOK, NRZ), Manchester OOK or M-ary pulse-position modulation (M-PPM: log2 M bits
    per symbol, the light on in one of M slots).

Channel (a simple documented imaging model; free space, no atmospheric loss)
    * flux through the receiver's aperture (area A = π(f/2N)²) at distance d, on axis:
      Φ_v = I_v·A·T_lens / d²  (lm)                                                     (1)
    * the LED is imaged to a disc of diameter D_img = max(D_led·f/d, 2.44·λ·N) (geometric
      image, at least the Airy disc), uniformly lit, centred on the middle pixel of the
      receiver's small pixel region: illuminance E_img = Φ_v / (π D_img²/4) (lux)        (2)
      For a resolved LED (2) is the extended-source law E = π L T/(4N²), L = I_v/(π D_led²/4),
      independent of d; an unresolved LED falls as 1/d².
    * each pixel gets E_img times the fraction of its area the disc covers, plus the
      ambient illuminance on the sensor plane ``ambient_lux`` (uniform);
      lux → photoelectrons by :class:`viform.light.radiometry.PixelOptics` (seed 000 §4.3).

Receiver
    The spike camera (seed 000 §3.2) with ``light_sample_ticks=1``; the scene hands the
    simulator the exact mean light of each tick (:class:`ModulatedSourceScene`), so the
    charge collected per tick is exact even when a slot edge falls inside a tick. The
    receiver knows the slot clock (in practice recovered from the preamble; timing recovery
    is not simulated, but the two clocks are not phase-locked) and where the LED's image
    is (it uses the pixels that get at least half the brightest pixel's LED light). A known
    preamble of on and off slots measures the mean spike counts per on slot μ₁ and per off
    slot μ₀. Each tick's spikes are assigned to the slot holding
    the tick's midpoint; the counts of the chosen pixels are summed per slot.
    OOK decides 1 when the count reaches θ = (μ₀ + μ₁)/2 (:func:`ook_threshold`: the counts
    are sub-Poisson, so the midpoint beats the Poisson ML threshold); Manchester compares the
    two halves; PPM takes the slot with the most spikes (ties and empty symbols → the
    earliest slot, an error unless that is the symbol sent).

Theory of the bit-error rate (seed 000 §5.1: the interval to Q electrons is Gamma(Q, λ))
    In a slot of duration T at photoelectron rate λ a pixel fires n̄ = λT/Q times on average.
    Its integrator keeps the charge left over between slots, so the count of a slot is
    sub-Poisson: variance n̄/Q (Fano factor 1/Q) + the pixel's phase at the two slot edges,
    i.e. ⌊μ⌋ or ⌈μ⌉ (μ its mean) with probabilities set by the fractional part of μ.

    * photon-starved (n̄_on < 1, no background): an on slot fires with probability n̄_on
      (the charge of ~1/n̄_on on slots is needed per spike) and off slots never fire. Every
      code here has one on slot per symbol (OOK: per one bit) and a lost symbol decodes to a
      fixed default (OOK 0, Manchester 0, PPM slot 0), wrong on average for half its bits:
      BER = ½·max(0, 1 − λ_on T/Q) for OOK, Manchester and M-PPM alike
      (:func:`starved_ber`; for PPM (1 − 1/M)·M/(2(M − 1)) = ½). The misses are regular,
      not independent: of N_on on slots, N_on·(1 − n̄_on) ± √(N_on·n̄_on/Q + 1/6) miss.
    * ambient light adds λ_b to every slot: b = λ_b T/Q spikes. OOK's midpoint threshold
      θ = b + n̄_on/2 then separates off counts {⌊b⌋, ⌈b⌉} from on counts
      {⌊b + n̄_on⌋, ⌈b + n̄_on⌉} only if n̄_on ≳ 2–3: with n̄_on ≈ 1 a background far below the
      clock's ceiling already costs BER ≈ ½·frac(b) (off slots reaching ⌈b⌉ ≥ θ; 0.25 at
      b = ½). With a few spikes per on slot the background only shifts μ₀, and errors
      appear once b + n̄_on approaches the number of ticks in a slot, where the
      one-spike-per-tick readout clips the on level; the BER tends to ½ when the background
      alone fires every tick.
    * the readout clock: a pixel reads at most one spike per tick, so a slot shorter than
      one tick (slot rate above ``clock_hz``) cannot be received at all and is refused;
      slots of a few ticks whose edges fall inside ticks share those ticks with their
      neighbours, and the inter-symbol interference raises the BER as the slot rate nears
      the clock (a saturated pixel at 1.1 ticks per slot: ≈ 0.2).

Error-free rate: the link is error-free when every on slot fires at least once and no off
slot fires: λ_on T/Q ≳ a few and λ_b T/Q ≪ 1, with T ≥ a couple of ticks;
:func:`max_error_free_rate` searches it by simulation, :func:`theoretical_rate_limits`
gives the photon and clock bounds.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
    check_range,
)
from viform.light.laser import F_NUMBER_RANGE
from viform.light.radiometry import PixelOptics
from viform.light.scenes import Scene
from viform.sensors.spike import SpikeSensor, SpikeSensorParameters

#: Modulations the receiver knows; "ppm" is 4-PPM.
MODULATIONS = ("ook", "manchester", "ppm", "ppm2", "ppm4", "ppm8", "ppm16")

#: Preamble slot pattern (1 = LED on): alternating pairs, so on and off slots follow both
#: on and off slots as in the payload.
PREAMBLE_SLOTS = np.array([1, 1, 0, 0] * 8, dtype=np.int8)


# ------------------------------------------------------------------ modulation

@dataclass(frozen=True)
class Modulation:
    """A line code: how bits become slots of LED on (1) / off (0) and back.

    Attributes
    ----------
    name : str
        ``"ook"``, ``"manchester"`` or ``"ppmM"`` (M = 2, 4, 8, 16; ``"ppm"`` = 4-PPM).
    bits_per_symbol : int
    slots_per_symbol : int
    """

    name: str
    bits_per_symbol: int
    slots_per_symbol: int

    @property
    def slots_per_bit(self) -> float:
        return self.slots_per_symbol / self.bits_per_symbol

    def slot_rate_hz(self, bitrate_bps: float) -> float:
        """Slots per second at ``bitrate_bps``."""
        return bitrate_bps * self.slots_per_bit

    def encode(self, bits) -> np.ndarray:
        """Slot levels (0/1, int8) for ``bits``; padded with zeros to whole symbols."""
        bits = check_bits(bits)
        if self.name == "ook":
            return bits.astype(np.int8)
        if self.name == "manchester":
            # 1 → on-off, 0 → off-on (IEEE 802.3 convention inverted is equally valid)
            return np.stack([bits, 1 - bits], axis=1).ravel().astype(np.int8)
        k = self.bits_per_symbol
        pad = (-bits.size) % k
        b = np.concatenate([bits, np.zeros(pad, np.uint8)]).reshape(-1, k)
        index = b @ (1 << np.arange(k - 1, -1, -1))
        slots = np.zeros((index.size, self.slots_per_symbol), np.int8)
        slots[np.arange(index.size), index] = 1
        return slots.ravel()

    def decode(self, counts, n_bits: int, threshold: float) -> np.ndarray:
        """Bits from the spike counts of each slot (see the module docstring for the rules)."""
        counts = np.asarray(counts, dtype=np.float64)
        if self.name == "ook":
            return (counts[:n_bits] >= max(threshold, 1e-9)).astype(np.uint8)
        if self.name == "manchester":
            c = counts[: 2 * n_bits].reshape(-1, 2)
            return (c[:, 0] > c[:, 1]).astype(np.uint8)
        m, k = self.slots_per_symbol, self.bits_per_symbol
        n_sym = -(-n_bits // k)
        index = np.argmax(counts[: n_sym * m].reshape(n_sym, m), axis=1)
        bits = (index[:, None] >> np.arange(k - 1, -1, -1)) & 1
        return bits.ravel()[:n_bits].astype(np.uint8)

    def n_slots(self, n_bits: int) -> int:
        return -(-n_bits // self.bits_per_symbol) * self.slots_per_symbol


def get_modulation(name: str) -> Modulation:
    """The :class:`Modulation` called ``name``; a clear error for one the receiver does not know."""
    if not isinstance(name, str) or name.lower() not in MODULATIONS:
        raise ViformError(f"modulation = {name!r} is not known to the receiver: choose one of "
                          f"{', '.join(MODULATIONS)}")
    name = name.lower()
    if name == "ook":
        return Modulation("ook", 1, 1)
    if name == "manchester":
        return Modulation("manchester", 1, 2)
    m = 4 if name == "ppm" else int(name[3:])
    return Modulation(f"ppm{m}", int(math.log2(m)), m)


def check_bits(bits) -> np.ndarray:
    """A non-empty 1-D array of 0/1 bits (uint8)."""
    arr = np.asarray(bits)
    if arr.size == 0:
        raise ViformError("payload is empty: give at least one bit to transmit")
    arr = arr.ravel()
    if not np.all((arr == 0) | (arr == 1)):
        raise ViformError("payload bits must be 0 or 1")
    return arr.astype(np.uint8)


def bytes_to_bits(data: bytes) -> np.ndarray:
    """Bits of ``data``, most significant bit first."""
    if len(data) == 0:
        raise ViformError("payload is empty: give at least one byte to transmit")
    return np.unpackbits(np.frombuffer(bytes(data), np.uint8))


def bits_to_bytes(bits) -> bytes:
    return np.packbits(np.asarray(bits, np.uint8)).tobytes()


def random_bits(n_bits: int, seed: int = 0) -> np.ndarray:
    n_bits = check_int("n_bits", n_bits, 1)
    return np.random.default_rng([seed, 0x1C0]).integers(0, 2, n_bits, dtype=np.uint8)


# ------------------------------------------------------------------ light

@dataclass(frozen=True)
class LEDTransmitter:
    """A modulated LED (or a display region) seen on axis.

    Attributes
    ----------
    luminous_intensity_cd : float
        On-axis luminous intensity when on, cd (a 5 mm indicator LED: ~0.01–1 cd).
    diameter_m : float
        Diameter of the emitting area, m.
    extinction_ratio : float
        Off level / on level, in [0, 1).
    """

    luminous_intensity_cd: float = 1.0
    diameter_m: float = 5e-3
    extinction_ratio: float = 0.0

    def __post_init__(self):
        check_positive("luminous_intensity_cd", self.luminous_intensity_cd)
        check_positive("diameter_m", self.diameter_m)
        check_range("extinction_ratio", self.extinction_ratio, 0.0, 1.0, high_open=True)

    @property
    def luminance_cd_per_m2(self) -> float:
        return self.luminous_intensity_cd / (math.pi * self.diameter_m ** 2 / 4)


@dataclass(frozen=True)
class ReceiverLens:
    """The spike camera's lens: focal length, f-number, transmission."""

    focal_length_m: float = 8e-3
    f_number: float = 2.0
    transmission: float = 0.9

    def __post_init__(self):
        check_positive("focal_length_m", self.focal_length_m)
        check_range("f_number", self.f_number, *F_NUMBER_RANGE)  # the same rule as every lens
        check_range("transmission", self.transmission, 0.0, 1.0, low_open=True)

    @property
    def aperture_area_m2(self) -> float:
        return math.pi * (self.focal_length_m / self.f_number) ** 2 / 4


def ambient_sensor_lux(scene_lux: float, reflectance: float = 0.5, lens: ReceiverLens | None = None) -> float:
    """Sensor-plane illuminance of a Lambertian background of ``reflectance`` lit by ``scene_lux``.

    Camera equation: E = π L T / (4N²) with L = ρ E_scene / π, so E = ρ E_scene T / (4N²).
    """
    lens = lens or ReceiverLens()
    check_non_negative("scene_lux", scene_lux)
    check_range("reflectance", reflectance, 0.0, 1.0)
    return reflectance * scene_lux * lens.transmission / (4 * lens.f_number ** 2)


def _disc_coverage(height: int, width: int, diameter_px: float, centre_rc, sub: int = 16) -> np.ndarray:
    """Fraction of each pixel's area inside a disc (supersampled; a sub-sample-sized disc → one pixel)."""
    cov = np.zeros((height, width))
    r = diameter_px / 2
    if diameter_px < 2.0 / sub:
        row, col = int(math.floor(centre_rc[0])), int(math.floor(centre_rc[1]))
        if 0 <= row < height and 0 <= col < width:
            cov[row, col] = math.pi * r * r
        return cov
    offs = (np.arange(sub) + 0.5) / sub
    yy = (np.arange(height)[:, None] + offs[None, :]).ravel()
    xx = (np.arange(width)[:, None] + offs[None, :]).ravel()
    inside = ((yy[:, None] - centre_rc[0]) ** 2 + (xx[None, :] - centre_rc[1]) ** 2) <= r * r
    cov = inside.reshape(height, sub, width, sub).mean(axis=(1, 3))
    # renormalise so the flux inside the region is exact (the supersampled area is approximate)
    inside_area = cov.sum()
    exact = _disc_area_in_region(r, centre_rc, height, width, sub)
    return cov * (exact / inside_area) if inside_area > 0 else cov


def _disc_area_in_region(r, centre_rc, height, width, sub):
    # the disc's area inside the region, by a finer grid only when it is clipped
    cy, cx = centre_rc
    if cy - r >= 0 and cx - r >= 0 and cy + r <= height and cx + r <= width:
        return math.pi * r * r
    fine = 4 * sub
    yy = (np.arange(height * fine) + 0.5) / fine
    xx = (np.arange(width * fine) + 0.5) / fine
    inside = ((yy[:, None] - cy) ** 2 + (xx[None, :] - cx) ** 2) <= r * r
    return inside.sum() / fine ** 2


@dataclass(frozen=True)
class LightLink:
    """An LED at ``distance_m`` imaged onto a small region of a spike camera (eqs. (1)–(2)).

    Attributes
    ----------
    transmitter : LEDTransmitter
    lens : ReceiverLens
    distance_m : float
    ambient_lux : float
        Ambient illuminance on the sensor plane, lux (uniform over the region);
        :func:`ambient_sensor_lux` converts a scene illuminance.
    sensor : SpikeSensorParameters
        The receiver (clock, threshold Q, dark current, optics).
    height, width : int
        Size of the receiving pixel region (small: BER sweeps stay fast).
    """

    transmitter: LEDTransmitter = field(default_factory=LEDTransmitter)
    lens: ReceiverLens = field(default_factory=ReceiverLens)
    distance_m: float = 10.0
    ambient_lux: float = 1.0
    sensor: SpikeSensorParameters = field(default_factory=SpikeSensorParameters)
    height: int = 8
    width: int = 8

    def __post_init__(self):
        check_positive("distance_m", self.distance_m)
        if self.distance_m <= self.lens.focal_length_m:
            raise ViformError(f"distance_m = {self.distance_m!r} must exceed the focal length "
                              f"{self.lens.focal_length_m:g} m")
        check_non_negative("ambient_lux", self.ambient_lux)
        check_int("height", self.height, 1, 256)
        check_int("width", self.width, 1, 256)

    @property
    def optics(self) -> PixelOptics:
        return self.sensor.optics

    @property
    def flux_lm(self) -> float:
        """Luminous flux entering the aperture from the LED when on, eq. (1)."""
        return (self.transmitter.luminous_intensity_cd * self.lens.aperture_area_m2 * self.lens.transmission
                / self.distance_m ** 2)

    @property
    def image_diameter_m(self) -> float:
        """Diameter of the LED's image disc on the sensor: geometric, at least the Airy disc."""
        f = self.lens.focal_length_m
        geometric = self.transmitter.diameter_m * f / (self.distance_m - f)
        airy = 2.44 * self.optics.wavelength_m * self.lens.f_number
        return max(geometric, airy)

    @property
    def image_lux(self) -> float:
        """Illuminance inside the LED's image disc when on, eq. (2)."""
        return self.flux_lm / (math.pi * self.image_diameter_m ** 2 / 4)

    def led_lux_map(self) -> np.ndarray:
        """Sensor-plane illuminance from the LED when on, per pixel (lux), shape (H, W)."""
        pitch = self.optics.pixel_pitch_m
        centre = (self.height // 2 + 0.5, self.width // 2 + 0.5)
        cov = _disc_coverage(self.height, self.width, self.image_diameter_m / pitch, centre)
        return self.image_lux * cov

    def electron_rates(self) -> dict:
        """Photoelectron rates (e⁻/s) of the brightest pixel and of the LED's whole image."""
        led = self.led_lux_map()
        e_lux = self.optics.electrons_per_lux_second
        return {
            "led_on_peak_pixel_e_per_s": float(led.max() * e_lux),
            "led_on_total_e_per_s": float(led.sum() * e_lux),
            "ambient_e_per_s": float(self.ambient_lux * e_lux),
            "dark_e_per_s": float(self.sensor.dark_current_e_per_s),
            "led_pixels": int(np.count_nonzero(led >= 0.5 * led.max())) if led.max() > 0 else 0,
        }

    def to_dict(self) -> dict:
        d = {"transmitter": asdict(self.transmitter), "lens": asdict(self.lens),
             "distance_m": self.distance_m, "ambient_lux": self.ambient_lux,
             "region_px": [self.height, self.width],
             "sensor": {"threshold_electrons": self.sensor.threshold_electrons, "clock_hz": self.sensor.clock_hz,
                        "dark_current_e_per_s": self.sensor.dark_current_e_per_s,
                        "pixel_pitch_m": self.optics.pixel_pitch_m,
                        "quantum_efficiency": self.optics.quantum_efficiency},
             "image_diameter_m": self.image_diameter_m, "image_lux": self.image_lux, "flux_lm": self.flux_lm,
             # the same ambient as a light-meter reading on a 50 % grey background (camera equation)
             "ambient_scene_lux_grey50": self.ambient_lux / ambient_sensor_lux(1.0, 0.5, self.lens)}
        d.update(self.electron_rates())
        return d


class ModulatedSourceScene(Scene):
    """Sensor-plane light of a modulated LED over ambient light: L(t) = A + E_led·level(t).

    ``level(t)`` is piecewise constant over slots of ``slot_s``: r + (1 − r)·s_i in slot i
    (s_i ∈ {0, 1}, r the extinction ratio), r before the first and after the last slot.

    With ``sample_window_s`` set (the spike simulator's tick), :meth:`illuminance_lux_many`
    returns the exact mean light over the window centred on each instant, so a sensor that
    samples the light at tick mid-points (``light_sample_ticks=1``) collects the exact
    charge of each tick even when a slot edge falls inside it.
    """

    name = "modulated-source"

    def __init__(self, led_lux, ambient_lux: float, slots, slot_s: float, extinction_ratio: float = 0.0,
                 start_s: float = 0.0, sample_window_s: float | None = None):
        led = np.asarray(led_lux, dtype=np.float64)
        if led.ndim != 2:
            raise ViformError(f"led_lux must be 2-D (H, W); got shape {led.shape}")
        super().__init__(*led.shape)
        self.led_lux = led
        self.ambient_lux = check_non_negative("ambient_lux", ambient_lux)
        self.slots = np.asarray(slots, dtype=np.float64).ravel()
        self.slot_s = check_positive("slot_s", slot_s)
        self.extinction_ratio = float(extinction_ratio)
        self.start_s = float(start_s)
        self.sample_window_s = sample_window_s
        levels = self.extinction_ratio + (1 - self.extinction_ratio) * self.slots
        self._levels = levels
        # cumulative ∫ level dt at slot edges (relative to the off level r outside the frame)
        self._cum = np.concatenate([[0.0], np.cumsum(levels - self.extinction_ratio)]) * self.slot_s

    @property
    def duration_frame_s(self) -> float:
        return self.slots.size * self.slot_s

    def level(self, t_s) -> np.ndarray:
        """Relative LED level at instants ``t_s`` (1 = on)."""
        t = np.asarray(t_s, dtype=np.float64)
        i = np.floor((t - self.start_s) / self.slot_s).astype(np.int64)
        ok = (i >= 0) & (i < self.slots.size)
        return np.where(ok, self._levels[np.clip(i, 0, self.slots.size - 1)], self.extinction_ratio)

    def _integral(self, t):
        # ∫_{start}^{t} (level − r) dt, exact for the piecewise-constant waveform
        x = np.clip((np.asarray(t, np.float64) - self.start_s) / self.slot_s, 0, self.slots.size)
        i = np.minimum(np.floor(x).astype(np.int64), self.slots.size - 1)
        return self._cum[i] + (x - i) * self.slot_s * (self._levels[i] - self.extinction_ratio)

    def mean_level(self, t0_s, t1_s) -> np.ndarray:
        """Exact mean relative level over [t0, t1] (arrays broadcast)."""
        t0, t1 = np.asarray(t0_s, np.float64), np.asarray(t1_s, np.float64)
        width = t1 - t0
        safe = np.where(width > 0, width, 1.0)
        mean = self.extinction_ratio + (self._integral(t1) - self._integral(t0)) / safe
        return np.where(width > 0, mean, self.level(t0))

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        return self.illuminance_lux_many([t_s])[0]

    def illuminance_lux_many(self, times_s) -> np.ndarray:
        t = np.asarray(times_s, dtype=np.float64).ravel()
        if self.sample_window_s:
            lev = self.mean_level(t - self.sample_window_s / 2, t + self.sample_window_s / 2)
        else:
            lev = self.level(t)
        return self.ambient_lux + lev[:, None, None] * self.led_lux[None]

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        return self.ambient_lux + float(self.mean_level(t0_s, t1_s)) * self.led_lux

    def describe(self) -> dict:
        d = super().describe()
        d.update({"slot_s": self.slot_s, "n_slots": int(self.slots.size), "ambient_lux": self.ambient_lux,
                  "extinction_ratio": self.extinction_ratio, "led_peak_lux": float(self.led_lux.max())})
        return d


# ------------------------------------------------------------------ link simulation

@dataclass
class LinkResult:
    """Outcome of one transmission."""

    bits_sent: np.ndarray
    bits_received: np.ndarray
    bitrate_bps: float
    modulation: str
    slot_s: float
    slot_ticks: float
    mu_on: float
    mu_off: float
    threshold: float
    pixels_used: int
    spikes_per_on_slot_pixel: float
    counts: np.ndarray = field(repr=False)
    slot_levels: np.ndarray = field(repr=False)
    payload_start_s: float = 0.0

    @property
    def n_bits(self) -> int:
        return int(self.bits_sent.size)

    @property
    def bit_errors(self) -> int:
        return int(np.count_nonzero(self.bits_sent != self.bits_received))

    @property
    def ber(self) -> float:
        return self.bit_errors / self.n_bits

    def summary(self) -> dict:
        return {"bitrate_bps": self.bitrate_bps, "modulation": self.modulation, "n_bits": self.n_bits,
                "bit_errors": self.bit_errors, "ber": self.ber, "ber_upper_95": ber_upper_bound(self.bit_errors,
                                                                                                 self.n_bits),
                "slot_s": self.slot_s, "slot_ticks": self.slot_ticks, "mu_on_spikes": self.mu_on,
                "mu_off_spikes": self.mu_off, "threshold_spikes": self.threshold, "pixels_used": self.pixels_used,
                "expected_spikes_per_on_slot_pixel": self.spikes_per_on_slot_pixel}


def ber_upper_bound(errors: int, n: int, confidence: float = 0.95) -> float:
    """One-sided Clopper–Pearson upper bound of the BER (3/n for zero errors at 95 %)."""
    from scipy.stats import beta

    if errors >= n:
        return 1.0
    return float(beta.ppf(confidence, errors + 1, n - errors))


def ook_threshold(mu_off: float, mu_on: float) -> float:
    """OOK decision threshold (spikes per slot): the midpoint θ = (μ₀ + μ₁)/2; a count ≥ θ is a one.

    The spike counts are sub-Poisson (intervals are Gamma(Q, λ), seed 000 §5.1, so the
    Fano factor of a count is ≈ 1/Q plus the ±1 of the slot edges), so the Poisson
    maximum-likelihood threshold (μ₁ − μ₀)/ln(μ₁/μ₀), which leans towards μ₀, lets single
    background spikes through; the midpoint does not. In the photon-starved case (μ₁ < 1,
    μ₀ ≈ 0) it reduces to "any spike is a one".
    """
    return 0.5 * (max(mu_off, 0.0) + max(mu_on, 0.0))


def slot_counts(spikes: np.ndarray, clock_hz: float, slot_s: float, start_s: float, n_slots: int,
                weights: np.ndarray | None = None) -> np.ndarray:
    """Spike counts per slot and pixel: tick k goes to the slot holding its midpoint.

    Returns (n_slots, P) counts (P = pixels), or (n_slots,) when ``weights`` (a pixel
    selection, shape P) is given.
    """
    t, h, w = spikes.shape
    edges = np.arange(n_slots + 1) * slot_s + start_s
    # first tick whose midpoint (k + ½)/f is ≥ each slot edge
    bounds = np.clip(np.ceil(edges * clock_hz - 0.5 - 1e-9), 0, t).astype(np.int64)
    flat = spikes.reshape(t, h * w)
    if weights is not None:
        flat = flat @ np.asarray(weights, np.float64)
        cs = np.concatenate([[0.0], np.cumsum(flat)])
    else:
        cs = np.concatenate([np.zeros((1, h * w), np.int64), np.cumsum(flat, axis=0, dtype=np.int64)])
    return (cs[bounds[1:]] - cs[bounds[:-1]]).astype(np.float64)


def check_rate(modulation: Modulation, bitrate_bps: float, clock_hz: float) -> float:
    """The slot duration; a clear error when a slot would be shorter than a readout tick."""
    check_positive("bitrate_bps", bitrate_bps)
    slot_rate = modulation.slot_rate_hz(bitrate_bps)
    if slot_rate > clock_hz * (1 + 1e-12):
        limit = clock_hz / modulation.slots_per_bit
        raise ViformError(
            f"bitrate_bps = {bitrate_bps:g} is above what the readout clock can resolve: {modulation.name} sends "
            f"{modulation.slots_per_bit:g} slot(s) per bit, i.e. {slot_rate:g} slots/s, but the spike camera "
            f"reads {clock_hz:g} ticks/s (one spike per pixel per tick); use at most {limit:g} bit/s")
    return 1.0 / slot_rate


def simulate_link(link: LightLink, bits, bitrate_bps: float, modulation: str = "ook", *, seed: int = 0,
                  guard_slots: int = 4, phase_ticks: float | None = None, return_spikes: bool = False):
    """Send ``bits`` over ``link`` and decode them from the spike camera's output.

    The frame is [guard (off)] [preamble, :data:`PREAMBLE_SLOTS`] [payload slots] [guard];
    it starts ``phase_ticks`` into the first tick (default: a uniformly random phase drawn
    from ``seed``; transmitter and camera clocks are not phase-locked, so slot edges fall
    inside ticks).

    Returns
    -------
    LinkResult (and the spike array (T, H, W) when ``return_spikes``).
    """
    mod = get_modulation(modulation)
    bits = check_bits(bits)
    clock = link.sensor.clock_hz
    slot_s = check_rate(mod, bitrate_bps, clock)
    guard = check_int("guard_slots", guard_slots, 0)
    payload = mod.encode(bits)
    slots = np.concatenate([np.zeros(guard, np.int8), PREAMBLE_SLOTS, payload, np.zeros(guard, np.int8)])
    tick_s = 1.0 / clock
    if phase_ticks is None:
        phase_ticks = float(np.random.default_rng([seed, 0x9A5E]).random())
    start_s = check_range("phase_ticks", phase_ticks, 0.0, 1.0, high_open=True) * tick_s
    scene = ModulatedSourceScene(link.led_lux_map(), link.ambient_lux, slots, slot_s,
                                 link.transmitter.extinction_ratio, start_s, sample_window_s=tick_s)
    duration = start_s + slots.size * slot_s + tick_s
    sensor = SpikeSensor(link.sensor)
    stream = sensor.capture(scene, duration, seed=seed, light_sample_ticks=1)
    spikes = stream.spikes
    n_slots = slots.size
    per_pixel = slot_counts(spikes, clock, slot_s, start_s, n_slots)
    pre = slice(guard, guard + PREAMBLE_SLOTS.size)
    pre_levels = PREAMBLE_SLOTS
    # the receiver knows where the LED's image is (located beforehand, e.g. by its flicker):
    # it uses the pixels that get at least half the brightest pixel's LED light
    led = link.led_lux_map().ravel()
    chosen = led >= 0.5 * led.max() if led.max() > 0 else np.ones(led.size, bool)
    combined = per_pixel[:, chosen].sum(axis=1)
    mu_on = float(combined[pre][pre_levels == 1].mean())
    mu_off = float(combined[pre][pre_levels == 0].mean())
    theta = ook_threshold(mu_off, mu_on)
    pay = combined[guard + PREAMBLE_SLOTS.size: guard + PREAMBLE_SLOTS.size + payload.size]
    received = mod.decode(pay, bits.size, theta)
    lam_on = float(link.led_lux_map().max() * link.optics.electrons_per_lux_second)
    result = LinkResult(bits, received, float(bitrate_bps), mod.name, slot_s, slot_s * clock, mu_on, mu_off, theta,
                        int(chosen.sum()), lam_on * slot_s / round(link.sensor.threshold_electrons), pay, payload,
                        start_s + (guard + PREAMBLE_SLOTS.size) * slot_s)
    return (result, spikes) if return_spikes else result


def ber(link: LightLink, bitrate_bps: float, modulation: str = "ook", n_bits: int = 512, seed: int = 0) -> dict:
    """BER of ``n_bits`` random bits (payload drawn from ``seed``) at ``bitrate_bps``."""
    r = simulate_link(link, random_bits(n_bits, seed), bitrate_bps, modulation, seed=seed)
    return r.summary()


# ------------------------------------------------------------------ theory

def starved_ber(spikes_per_on_slot: float) -> float:
    """Photon-starved BER without background, OOK, Manchester and M-PPM: ½·max(0, 1 − λ_on T/Q)
    (module docstring)."""
    return 0.5 * max(0.0, 1.0 - check_non_negative("spikes_per_on_slot", spikes_per_on_slot))


def theoretical_rate_limits(link: LightLink, modulation: str = "ook", spikes_needed: float = 3.0,
                            min_slot_ticks: float = 2.0) -> dict:
    """Bit-rate bounds of a link: photons (≥ ``spikes_needed`` spikes per on slot in the best
    pixel) and clock (slots ≥ ``min_slot_ticks`` ticks)."""
    mod = get_modulation(modulation)
    rates = link.electron_rates()
    q = round(link.sensor.threshold_electrons)
    lam = rates["led_on_peak_pixel_e_per_s"]
    photon_slot_rate = lam / (q * spikes_needed) if lam > 0 else 0.0
    clock_slot_rate = link.sensor.clock_hz / min_slot_ticks
    return {
        "photon_limited_bps": photon_slot_rate / mod.slots_per_bit,
        "clock_limited_bps": clock_slot_rate / mod.slots_per_bit,
        "bound_bps": min(photon_slot_rate, clock_slot_rate) / mod.slots_per_bit,
        "absolute_clock_limit_bps": link.sensor.clock_hz / mod.slots_per_bit,
        "spikes_needed_per_on_slot": spikes_needed,
        "background_spikes_per_s": (rates["ambient_e_per_s"] + rates["dark_e_per_s"]) / q,
    }


def max_error_free_rate(link: LightLink, modulation: str = "ook", n_bits: int = 400, seed: int = 0,
                        steps_per_octave: int = 4, min_bps: float | None = None,
                        max_ticks: float = 4e6, max_ticks_per_try: float = 1e6) -> dict:
    """Highest bit rate (on a geometric grid below the clock limit) with zero errors in ``n_bits``,
    confirmed with a second seed.

    The grid is the clock limit (one slot per tick) divided by powers of 2^(1/``steps_per_octave``),
    from the highest rate at which an on slot still gets more than half a spike (faster is
    photon-starved, BER ≳ ¼) down to ``min_bps`` (default: the clock limit / 2^12). The search
    stops once the rates tried have cost ``max_ticks`` sensor ticks in all (a slower rate costs
    more ticks per bit); ``searched_down_to_bps`` then says how far it went. No rate is tried
    whose one run would hold more than ``max_ticks_per_try`` ticks (about 1 kB of memory each:
    the CLI's per-run limit).
    """
    mod = get_modulation(modulation)
    factor = 2 ** (1 / check_int("steps_per_octave", steps_per_octave, 1))
    rate = link.sensor.clock_hz / mod.slots_per_bit
    lo = check_positive("min_bps", min_bps if min_bps is not None else rate / 4096)
    lo = max(lo, n_bits * link.sensor.clock_hz / max_ticks_per_try)  # one try holds all its ticks
    # skip the grid rates where an on slot gets under half a spike (BER > ¼ by the theory)
    starved = theoretical_rate_limits(link, modulation, spikes_needed=0.5)["photon_limited_bps"]
    while rate > starved and rate / factor >= lo * (1 - 1e-9):
        rate /= factor
    tried = []
    spent = 0.0
    while rate >= lo * (1 - 1e-9):
        cost = 2 * n_bits * link.sensor.clock_hz / rate  # ticks of this try and its confirmation, at most
        if tried and spent + cost > max_ticks:
            break
        spent += cost
        r = ber(link, rate, modulation, n_bits, seed)
        tried.append({"bitrate_bps": rate, "bit_errors": r["bit_errors"], "ber": r["ber"]})
        if r["bit_errors"] == 0:
            r2 = ber(link, rate, modulation, n_bits, seed + 1)
            tried[-1]["confirm_bit_errors"] = r2["bit_errors"]
            if r2["bit_errors"] == 0:
                return {"max_error_free_bps": rate, "n_bits_checked": 2 * n_bits,
                        "ber_upper_95": ber_upper_bound(0, 2 * n_bits), "tried": tried,
                        "searched_down_to_bps": rate}
        rate /= factor
    return {"max_error_free_bps": None, "n_bits_checked": 0, "ber_upper_95": None, "tried": tried,
            "searched_down_to_bps": tried[-1]["bitrate_bps"] if tried else None}


def sweep(link: LightLink, parameter: str, values, bitrate_bps: float, modulation: str = "ook",
          n_bits: int = 400, seed: int = 0) -> list[dict]:
    """BER against ``parameter`` ∈ {"bitrate_bps", "distance_m", "ambient_lux"}."""
    from dataclasses import replace

    check_choice("parameter", parameter, ("bitrate_bps", "distance_m", "ambient_lux"))
    rows = []
    for v in values:
        lk, rate = link, bitrate_bps
        if parameter == "bitrate_bps":
            rate = float(v)
        else:
            lk = replace(link, **{parameter: float(v)})
        r = ber(lk, rate, modulation, n_bits, seed)
        rates = lk.electron_rates()
        q = round(lk.sensor.threshold_electrons)
        slot_s = 1.0 / get_modulation(modulation).slot_rate_hz(rate)
        r.update({parameter: float(v),
                  "background_spikes_per_slot_pixel": (rates["ambient_e_per_s"] + rates["dark_e_per_s"]) * slot_s / q})
        rows.append(r)
    return rows
