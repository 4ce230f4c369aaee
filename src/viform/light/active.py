"""Active (laser-illuminated) scenes: range, reflectance, retroreflectors, fog, ambient light.

Seed 004 (introduction): range gating exploits the finite speed of light; the scene is lit
by short pulses and the receiver opens a delay 2R/c after each pulse so that light
scattered by dust or fog closer than R is not recorded. This module computes, from
physics in SI units, the photoelectrons a pixel collects from one laser pulse inside a
time window [t_open, t_close] measured from the start of the pulse, and the steady
ambient photoelectron rate.

Link budget (monostatic, top-hat beam of solid angle Ω_b, rectangular pulse of peak
power P and length τ, receiver f-number N, transmission τ_r, pixel area A_p):

* irradiance on a surface at range R:  E_t = P·T(R) / (Ω_b R²),       T(R) = exp(−σR)  (1)
* radiance back towards the receiver:  L = E_t·T(R)·(ρ/π + R_A)                       (2)
  (Lambertian reflectance ρ; R_A the coefficient of retroreflection, sr⁻¹ = cd lx⁻¹ m⁻²)
* power on the pixel:  Φ = A_p·π τ_r L / (4N²)  (camera equation, on axis)            (3)
* a sub-pixel retroreflector of CIL (m²/sr = cd/lx): Φ = CIL·E_t·T(R)·A_rx τ_r / R²   (4)
* fog, single scattering, volume backscatter β_π = σ/S (lidar ratio S, sr):
  dΦ = A_p π τ_r β_π P T(r)² O(r) / (4N² Ω_b r²) dr                                   (5)

Energy inside the window = Φ/P · P·w(r), with w(r) the overlap (s) of the return
[2r/c, 2r/c + τ] with [t_open, t_close] (:func:`window_overlap_s`). Photoelectrons =
energy/(hc/λ)·QE. Surfaces thus fall as 1/R², point retroreflectors as 1/R⁴.

Meteorological visibility V gives σ by Koschmieder, σ = 3.912/V (2 % contrast threshold);
wavelength-independent, which holds for fog (droplets ≫ λ) and over-estimates σ at 905 nm
for haze (Kim et al. 2001, selectable with ``model="kim"``).

Ambient light: sun-lit scene of illuminance E_v (lux, night ≈ 1e-3 … sunny day ≈ 1e5).
Lux weights the spectrum with V(λ) and says nothing about 905 nm, so the in-band
irradiance is taken from a 5778 K black-body sun scaled to the same illuminance:
E_λ(905 nm)/E_v = B_λ(905)/(683 ∫B_λV dλ) ≈ 7.2e-6 W m⁻² nm⁻¹ lx⁻¹ (0.72 W m⁻² nm⁻¹ at
1e5 lx; ASTM G173 AM1.5G gives ≈ 0.75–0.8 W m⁻² nm⁻¹ at ~1.1e5 lx, within 10 %). Only the
filter band (``Receiver.filter_bandwidth_m``) reaches the sensor. Fog adds airlight
L_h (1 − T(R)) with horizon radiance L_h = k_sky·E/π.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
    check_range,
)
from viform.light.laser import LASER_WAVELENGTH_M, PulsedLaser, Receiver
from viform.light.radiometry import (
    LUMINOUS_EFFICACY_LM_PER_W,
    PLANCK_J_S,
    SPEED_OF_LIGHT_M_PER_S,
    photon_energy_j,
)

#: Koschmieder constant, −ln(0.02): σ = 3.912 / V.
KOSCHMIEDER = 3.912
#: Black-body temperature used for the solar spectral shape, K.
SUN_TEMPERATURE_K = 5778.0
#: Ambient illuminance presets, lux (scene illuminance, not on the sensor).
AMBIENT_PRESETS_LUX = {
    "night": 1e-3,
    "full-moon": 0.25,
    "twilight": 10.0,
    "overcast": 1e3,
    "daylight": 1e4,
    "sunny": 1e5,
}
_BOLTZMANN_J_PER_K = 1.380649e-23


def extinction_per_m(
    visibility_m: float, wavelength_m: float = LASER_WAVELENGTH_M, model: str = "koschmieder"
) -> float:
    """Extinction coefficient σ (1/m) from meteorological visibility (Koschmieder σ = 3.912/V).

    ``model="kim"`` applies Kim, Mcarthur & Korevaar (2001), σ = 3.912/V·(λ/550 nm)^−q,
    q = 1.6 (V > 50 km), 1.3 (6–50 km), 0.16V + 0.34 (1–6 km), V − 0.5 (0.5–1 km), 0 (< 0.5 km).
    """
    v = check_positive("visibility_m", visibility_m, allow_inf=True)
    check_choice("model", model, ("koschmieder", "kim"))
    if math.isinf(v):
        return 0.0
    sigma = KOSCHMIEDER / v
    if model == "kim":
        vk = v / 1000.0
        q = 1.6 if vk > 50 else 1.3 if vk > 6 else 0.16 * vk + 0.34 if vk > 1 else max(vk - 0.5, 0.0)
        sigma *= (check_positive("wavelength_m", wavelength_m) / 550e-9) ** (-q)
    return sigma


@dataclass(frozen=True)
class Medium:
    """A homogeneous participating medium along every line of sight.

    Attributes
    ----------
    extinction_per_m : float
        σ, 1/m (0 = vacuum).
    lidar_ratio_sr : float
        S = σ/β_π, sr: ≈ 18 sr for water fog, 30–60 sr for dust and smoke.
    name : str
        Label for reports.
    """

    extinction_per_m: float = 0.0
    lidar_ratio_sr: float = 18.0
    name: str = "clear"

    def __post_init__(self):
        check_non_negative("extinction_per_m", self.extinction_per_m)
        check_positive("lidar_ratio_sr", self.lidar_ratio_sr)

    @classmethod
    def from_visibility(
        cls,
        visibility_m: float,
        lidar_ratio_sr: float = 18.0,
        name: str | None = None,
        wavelength_m: float = LASER_WAVELENGTH_M,
        model: str = "koschmieder",
    ) -> Medium:
        """Medium with σ = 3.912/V (visibility_m may be ``inf`` for vacuum)."""
        sigma = extinction_per_m(visibility_m, wavelength_m, model)
        label = name or (f"visibility {visibility_m:g} m" if math.isfinite(float(visibility_m)) else "clear")
        return cls(sigma, lidar_ratio_sr, label)

    @property
    def visibility_m(self) -> float:
        return math.inf if self.extinction_per_m == 0 else KOSCHMIEDER / self.extinction_per_m

    @property
    def backscatter_per_m_sr(self) -> float:
        """Volume backscatter coefficient β_π = σ/S, 1/(m·sr)."""
        return self.extinction_per_m / self.lidar_ratio_sr

    def transmission(self, range_m):
        """One-way transmission exp(−σR)."""
        return np.exp(-self.extinction_per_m * np.asarray(range_m, dtype=np.float64))


@functools.lru_cache(maxsize=32)
def solar_spectral_irradiance_per_lux(wavelength_m: float = LASER_WAVELENGTH_M) -> float:
    """Solar spectral irradiance per lux of illuminance, W m⁻² m⁻¹ lx⁻¹ (5778 K black body).

    The CIE photopic curve is the Gaussian fit V(λ) = 1.019 exp(−285.4 (λ/µm − 0.559)²).
    Gives 7.2e-6 W m⁻² nm⁻¹ lx⁻¹ at 905 nm.
    """
    check_positive("wavelength_m", wavelength_m)
    c, h, k, t = SPEED_OF_LIGHT_M_PER_S, PLANCK_J_S, _BOLTZMANN_J_PER_K, SUN_TEMPERATURE_K

    def planck(lam):
        return 2 * h * c**2 / lam**5 / np.expm1(h * c / (lam * k * t))

    lam = np.linspace(360e-9, 830e-9, 4000)
    v = 1.019 * np.exp(-285.4 * (lam * 1e6 - 0.559) ** 2)
    lux_per_unit = LUMINOUS_EFFICACY_LM_PER_W * np.trapezoid(planck(lam) * v, lam)
    return float(planck(wavelength_m) / lux_per_unit)


def solar_band_irradiance_w_per_m2(ambient_lux, receiver: Receiver):
    """Sunlight irradiance (W/m²) inside the receiver filter band for scene illuminance ``ambient_lux``."""
    lux = check_non_negative("ambient_lux", ambient_lux)
    return lux * solar_spectral_irradiance_per_lux(receiver.filter_center_m) * receiver.filter_bandwidth_m


@dataclass(frozen=True)
class PointRetroreflector:
    """A sub-pixel retroreflector ("катафот", seed 004 field test) at a pixel position.

    CIL = η·A / Ω_r (m²/sr = cd/lx): a fraction η of the intercepted light goes back into a
    cone of half-angle θ_r (Ω_r = πθ_r²). Defaults: an 80 mm plastic reflector, η = 0.3,
    θ_r = 0.5° → CIL ≈ 6.3 cd/lx (an assumption; the seed gives no reflector data).
    """

    range_m: float
    row: float
    col: float
    diameter_m: float = 0.08
    efficiency: float = 0.3
    divergence_half_angle_rad: float = math.radians(0.5)
    label: str = ""

    def __post_init__(self):
        check_non_negative("range_m", self.range_m)
        check_positive("diameter_m", self.diameter_m)
        check_range("efficiency", self.efficiency, 0.0, 1.0, low_open=True)
        check_range("divergence_half_angle_rad", self.divergence_half_angle_rad, 0.0, math.pi / 2, low_open=True)

    @property
    def cil_m2_per_sr(self) -> float:
        """Coefficient of luminous intensity (radiometric equivalent), m²/sr."""
        area = math.pi * self.diameter_m**2 / 4
        return self.efficiency * area / (math.pi * self.divergence_half_angle_rad**2)


def window_overlap_s(range_m, pulse_width_s: float, open_s: float, close_s: float):
    """Seconds of a rectangular return from ``range_m`` that fall in [open_s, close_s].

    The return from range r lasts [2r/c, 2r/c + τ]. ``open_s = -inf`` / ``close_s = inf``
    give an un-gated window.
    """
    arrival = 2.0 * np.asarray(range_m, dtype=np.float64) / SPEED_OF_LIGHT_M_PER_S
    start = np.maximum(arrival, open_s)
    end = np.minimum(arrival + pulse_width_s, close_s)
    return np.clip(end - start, 0.0, None)


@dataclass
class ActiveScene:
    """What a laser-illuminated pixel looks at.

    Attributes
    ----------
    range_m : ndarray (H, W)
        Distance along each pixel's line of sight to the first surface, m (``inf`` = sky).
    reflectance : ndarray (H, W)
        Lambertian reflectance at 905 nm, [0, 1].
    retro_coefficient_per_sr : ndarray (H, W) or None
        R_A of retroreflective surfaces (sheeting), sr⁻¹ (= cd lx⁻¹ m⁻²); 0 elsewhere.
    retroreflectors : list of PointRetroreflector
        Sub-pixel retroreflectors, added on top of the pixel's background.
    medium : Medium
    ambient_lux : float
        Scene illuminance of the steady background light (sun, sky), lux.
    sky_radiance_factor : float
        Horizon sky radiance as a fraction of E/π in the filter band (airlight, sky pixels).
    name : str
    """

    range_m: np.ndarray
    reflectance: np.ndarray
    retro_coefficient_per_sr: np.ndarray | None = None
    retroreflectors: list = field(default_factory=list)
    medium: Medium = field(default_factory=Medium)
    ambient_lux: float = 0.0
    sky_radiance_factor: float = 0.3
    name: str = "active"

    def __post_init__(self):
        self.range_m = np.asarray(self.range_m, dtype=np.float64)
        if self.range_m.ndim != 2:
            raise ViformError(f"range_m must be a 2-D (H, W) array, got shape {self.range_m.shape}")
        if np.any(np.isnan(self.range_m)) or np.any(self.range_m < 0):
            raise ViformError("range_m has negative or NaN values; ranges must be ≥ 0 m (inf = sky)")
        self.reflectance = np.broadcast_to(np.asarray(self.reflectance, dtype=np.float64), self.range_m.shape).copy()
        if np.any(~np.isfinite(self.reflectance)) or self.reflectance.min() < 0 or self.reflectance.max() > 1:
            raise ViformError("reflectance must lie in [0, 1] for every pixel")
        ra = 0.0 if self.retro_coefficient_per_sr is None else self.retro_coefficient_per_sr
        self.retro_coefficient_per_sr = np.broadcast_to(np.asarray(ra, dtype=np.float64), self.range_m.shape).copy()
        if np.any(~np.isfinite(self.retro_coefficient_per_sr)) or self.retro_coefficient_per_sr.min() < 0:
            raise ViformError("retro_coefficient_per_sr must be finite and ≥ 0 sr⁻¹")
        check_non_negative("ambient_lux", self.ambient_lux)
        check_non_negative("sky_radiance_factor", self.sky_radiance_factor)
        for r in self.retroreflectors:
            if not (0 <= r.row < self.height and 0 <= r.col < self.width):
                raise ViformError(
                    f"retroreflector at row {r.row}, col {r.col} lies outside the {self.height}x{self.width} scene"
                )

    @property
    def height(self) -> int:
        return self.range_m.shape[0]

    @property
    def width(self) -> int:
        return self.range_m.shape[1]

    @property
    def shape(self) -> tuple[int, int]:
        return self.range_m.shape

    def with_(self, **changes) -> ActiveScene:
        """A copy with some attributes replaced (e.g. ``medium`` or ``ambient_lux``)."""
        kw = {
            k: getattr(self, k)
            for k in (
                "range_m",
                "reflectance",
                "retro_coefficient_per_sr",
                "retroreflectors",
                "medium",
                "ambient_lux",
                "sky_radiance_factor",
                "name",
            )
        }
        kw.update(changes)
        return ActiveScene(**kw)

    def describe(self) -> dict:
        finite = self.range_m[np.isfinite(self.range_m)]
        return {
            "name": self.name,
            "height": self.height,
            "width": self.width,
            "range_min_m": float(finite.min()) if finite.size else None,
            "range_max_m": float(finite.max()) if finite.size else None,
            "medium": self.medium.name,
            "extinction_per_m": self.medium.extinction_per_m,
            "visibility_m": self.medium.visibility_m,
            "lidar_ratio_sr": self.medium.lidar_ratio_sr,
            "ambient_lux": self.ambient_lux,
            "retroreflectors": [
                {"range_m": r.range_m, "row": r.row, "col": r.col, "cil_m2_per_sr": r.cil_m2_per_sr, "label": r.label}
                for r in self.retroreflectors
            ],
        }


@dataclass(frozen=True)
class ActiveImagingGeometry:
    """Emitter + receiver + pixel: converts a scene into photoelectrons (eqs. 1–5).

    Attributes
    ----------
    laser : PulsedLaser
    receiver : Receiver
    pixel_pitch_m : float
    quantum_efficiency : float
        At the laser wavelength (photoelectrons per photon, fill factor included).
    sensor_height_px, sensor_width_px : int
        Full sensor format; a top-hat beam matched to it sets Ω_b (a simulated scene can be a
        window of it without changing the physics).
    """

    laser: PulsedLaser = field(default_factory=PulsedLaser)
    receiver: Receiver = field(default_factory=Receiver)
    pixel_pitch_m: float = 5.6e-6
    quantum_efficiency: float = 0.25
    sensor_height_px: int = 494
    sensor_width_px: int = 659

    def __post_init__(self):
        check_positive("pixel_pitch_m", self.pixel_pitch_m)
        check_range("quantum_efficiency", self.quantum_efficiency, 0.0, 1.0, low_open=True)
        check_int("sensor_height_px", self.sensor_height_px, 1)
        check_int("sensor_width_px", self.sensor_width_px, 1)

    @property
    def ifov_rad(self) -> float:
        return self.receiver.ifov_rad(self.pixel_pitch_m)

    @property
    def beam_solid_angle_sr(self) -> float:
        """Ω_b of the top-hat beam: the laser's divergence, or the full-sensor FOV if unset."""
        dx = self.laser.divergence_x_rad or 2 * math.atan(
            self.sensor_width_px * self.pixel_pitch_m / (2 * self.receiver.focal_length_m)
        )
        dy = self.laser.divergence_y_rad or 2 * math.atan(
            self.sensor_height_px * self.pixel_pitch_m / (2 * self.receiver.focal_length_m)
        )
        return 4 * math.asin(math.sin(dx / 2) * math.sin(dy / 2))  # rectangular pyramid

    @property
    def _electrons_per_joule(self) -> float:
        return self.quantum_efficiency / photon_energy_j(self.laser.wavelength_m)

    @property
    def _camera_factor_m2(self) -> float:
        """A_p·π·τ_r/(4N²): pixel power per unit scene radiance (eq. 3), m²·sr."""
        r = self.receiver
        return self.pixel_pitch_m**2 * math.pi * r.transmission / (4 * r.f_number**2)

    def overlap(self, range_m):
        """Biaxial overlap O(r) = 1 − exp(−(r/r_o)²)."""
        return -np.expm1(-((np.asarray(range_m, dtype=np.float64) / self.receiver.overlap_range_m) ** 2))

    # ------------------------------------------------------------------ per pulse
    def surface_electrons(self, scene: ActiveScene, open_s: float = -np.inf, close_s: float = np.inf):
        """Expected photoelectrons per pulse from surfaces (Lambertian + retro sheeting), (H, W)."""
        r = scene.range_m
        finite = np.isfinite(r) & (r > 0)
        rr = np.where(finite, r, 1.0)
        t = scene.medium.transmission(rr)
        radiance_per_w = (
            t * t / (self.beam_solid_angle_sr * rr**2) * (scene.reflectance / math.pi + scene.retro_coefficient_per_sr)
        )
        w = window_overlap_s(rr, self.laser.pulse_width_s, open_s, close_s)
        joules = (
            self.laser.peak_power_w
            * self.laser.transmitter_efficiency
            * w
            * self._camera_factor_m2
            * radiance_per_w
            * self.overlap(rr)
        )
        return np.where(finite, joules * self._electrons_per_joule, 0.0)

    def retroreflector_electrons(
        self, scene: ActiveScene, open_s: float = -np.inf, close_s: float = np.inf, psf_sigma_px: float = 0.5
    ):
        """Expected photoelectrons per pulse from the sub-pixel retroreflectors (eq. 4), (H, W).

        Each image is spread by a Gaussian blur of ``psf_sigma_px`` (lens + defocus), integrated
        over pixel areas, plus the reflector's own angular size.
        """
        out = np.zeros(scene.shape)
        p = self.laser.peak_power_w * self.laser.transmitter_efficiency
        for rr in scene.retroreflectors:
            if rr.range_m <= 0:
                continue
            t = float(scene.medium.transmission(rr.range_m))
            e_t = p * t / (self.beam_solid_angle_sr * rr.range_m**2)
            watts = (
                rr.cil_m2_per_sr * e_t * t * self.receiver.aperture_area_m2 * self.receiver.transmission / rr.range_m**2
            ) * float(self.overlap(rr.range_m))
            w = float(window_overlap_s(rr.range_m, self.laser.pulse_width_s, open_s, close_s))
            size_px = rr.diameter_m / rr.range_m / self.ifov_rad
            sigma = math.hypot(psf_sigma_px, size_px / 4.0)  # disc of diameter d ≈ Gaussian σ = d/4
            out += watts * w * self._electrons_per_joule * _gaussian_spot(scene.shape, rr.row, rr.col, sigma)
        return out

    def backscatter_electrons(
        self, scene: ActiveScene, open_s: float = -np.inf, close_s: float = np.inf, n_grid: int = 1500
    ):
        """Expected photoelectrons per pulse from the medium between the receiver and the surface (eq. 5).

        Integrated numerically over r, up to each pixel's range (the surface hides what is
        behind it); the window-overlap function w(r) rejects the medium before the gate.
        """
        m = scene.medium
        if m.extinction_per_m == 0:
            return np.zeros(scene.shape)
        c = SPEED_OF_LIGHT_M_PER_S
        tau = self.laser.pulse_width_s
        far = 30.0 / m.extinction_per_m  # T² = e^-60 beyond: nothing comes back
        finite = scene.range_m[np.isfinite(scene.range_m)]
        r_max = min(far, float(finite.max()) if finite.size else far)
        r_max = max(r_max, 1.0)
        lo, hi = 1e-3 * self.receiver.overlap_range_m, r_max
        grid = [np.geomspace(lo, hi, n_grid)]
        if np.isfinite(open_s) or np.isfinite(close_s):
            g0 = max(lo, (open_s * c / 2 - c * tau / 2) if np.isfinite(open_s) else lo)
            g1 = min(hi, close_s * c / 2 if np.isfinite(close_s) else hi)
            if g1 > g0:
                grid.append(np.linspace(g0, g1, n_grid))
        r = np.unique(np.concatenate(grid))
        t2 = m.transmission(r) ** 2
        w = window_overlap_s(r, tau, open_s, close_s)
        integrand = t2 * self.overlap(r) * w / r**2
        cumulative = integrand[0] * r[0] + np.concatenate(
            [[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(r))]
        )
        per_pixel = np.interp(np.where(np.isfinite(scene.range_m), scene.range_m, hi), r, cumulative)
        k = (
            self.laser.peak_power_w
            * self.laser.transmitter_efficiency
            * self._camera_factor_m2
            * m.backscatter_per_m_sr
            / self.beam_solid_angle_sr
        )
        return k * per_pixel * self._electrons_per_joule

    def laser_electrons(self, scene: ActiveScene, open_s: float = -np.inf, close_s: float = np.inf) -> dict:
        """All laser contributions per pulse in a window: surface, retroreflectors, backscatter, total."""
        parts = {
            "surface": self.surface_electrons(scene, open_s, close_s),
            "retroreflectors": self.retroreflector_electrons(scene, open_s, close_s),
            "backscatter": self.backscatter_electrons(scene, open_s, close_s),
        }
        parts["total"] = parts["surface"] + parts["retroreflectors"] + parts["backscatter"]
        return parts

    # ------------------------------------------------------------------ ambient
    def ambient_electrons_per_s(self, scene: ActiveScene):
        """Steady ambient photoelectron rate per pixel (sun-lit surfaces + airlight/sky), e⁻/s, (H, W)."""
        e_band = float(solar_band_irradiance_w_per_m2(scene.ambient_lux, self.receiver))
        l_horizon = scene.sky_radiance_factor * e_band / math.pi
        r = scene.range_m
        finite = np.isfinite(r)
        t = np.where(finite, scene.medium.transmission(np.where(finite, r, 0.0)), 0.0)
        radiance = scene.reflectance * e_band / math.pi * t + l_horizon * (1.0 - t)
        watts = self._camera_factor_m2 * radiance
        return watts * self._electrons_per_joule

    def to_dict(self) -> dict:
        return {
            "laser": self.laser.to_dict(),
            "receiver": self.receiver.to_dict(),
            "pixel_pitch_m": self.pixel_pitch_m,
            "quantum_efficiency": self.quantum_efficiency,
            "sensor_height_px": self.sensor_height_px,
            "sensor_width_px": self.sensor_width_px,
            "ifov_rad": self.ifov_rad,
            "beam_solid_angle_sr": self.beam_solid_angle_sr,
        }


def _gaussian_spot(shape, row: float, col: float, sigma_px: float) -> np.ndarray:
    """Fraction of a Gaussian spot (centre row, col in pixel-centre coordinates) on each pixel."""
    from scipy.special import erf

    def axis(n, centre):
        edges = np.arange(n + 1) - 0.5
        cdf = 0.5 * (1 + erf((edges - centre) / (math.sqrt(2) * sigma_px)))
        return np.diff(cdf)

    return np.outer(axis(shape[0], row), axis(shape[1], col))


# ---------------------------------------------------------------------- scenes
def field_test_scene(
    height: int = 64,
    width: int = 96,
    ranges_m=(50.0, 100.0, 200.0, 300.0),
    background_range_m: float = 1000.0,
    background_reflectance: float = 0.3,
    ambient_lux: float = 1e5,
    visibility_m: float = 20e3,
    retro: dict | None = None,
) -> ActiveScene:
    """Seed 004 field test: retroreflectors at 50, 100, 200, 300 m in front of a distant background.

    The background (vegetation/ground, ρ = 0.3 at 905 nm) is put far behind the gate so
    that only the reflectors can appear; clear air (20 km visibility) and sunny-day ambient
    light by default.

    Parameters
    ----------
    height, width : int
        Size, pixels.
    ranges_m : sequence of float
        Range of each retroreflector, m.
    background_range_m : float
        Range of the background, m.
    background_reflectance : float
        Lambertian reflectance of the background at 905 nm, in [0, 1].
    ambient_lux : float
        Ambient (solar) illuminance, lux.
    visibility_m : float
        Meteorological visibility of the air, m.
    retro : dict, optional
        Overrides of the retroreflectors' :class:`PointRetroreflector` fields.

    Returns
    -------
    ActiveScene
        The scene, for :class:`~viform.sensors.GatedInterlineCCD`.
    """
    check_int("height", height, 8)
    check_int("width", width, 8)
    ranges = [check_non_negative("ranges_m", r) for r in ranges_m]
    n = len(ranges)
    cols = (np.arange(n) + 0.5) * width / n
    retros = [
        PointRetroreflector(range_m=r, row=height / 2, col=float(c), label=f"{r:g} m", **(retro or {}))
        for r, c in zip(ranges, cols, strict=True)
    ]
    return ActiveScene(
        range_m=np.full((height, width), float(background_range_m)),
        reflectance=background_reflectance,
        retroreflectors=retros,
        medium=Medium.from_visibility(visibility_m),
        ambient_lux=ambient_lux,
        name="field test (seed 004)",
    )


def fog_scene(
    height: int = 64,
    width: int = 96,
    visibility_m: float = 150.0,
    ambient_lux: float = 1e-3,
    sign_ranges_m=(60.0, 90.0, 120.0),
    sign_retro_per_sr: float = 50.0,
    background_range_m: float = 400.0,
) -> ActiveScene:
    """Road scene in fog: retroreflective sign panels (R_A sheeting) at several ranges behind fog.

    Panels are square, ~1.2 m wide at their range; the rest is a Lambertian background
    (ρ = 0.3) at ``background_range_m``; the fog fills the space in front.

    Parameters
    ----------
    height, width : int
        Size, pixels.
    visibility_m : float
        Meteorological visibility in the fog, m.
    ambient_lux : float
        Ambient illuminance, lux (night by default).
    sign_ranges_m : sequence of float
        Range of each sign panel, m.
    sign_retro_per_sr : float
        Coefficient of retroreflection R_A of the sheeting, sr⁻¹ (= cd lx⁻¹ m⁻²).
    background_range_m : float
        Range of the background, m.

    Returns
    -------
    ActiveScene
        The scene, for :class:`~viform.sensors.GatedInterlineCCD`.
    """
    check_int("height", height, 8)
    check_int("width", width, 8)
    rng_m = np.full((height, width), float(background_range_m))
    refl = np.full((height, width), 0.3)
    ra = np.zeros((height, width))
    n = len(sign_ranges_m)
    ifov = ActiveImagingGeometry().ifov_rad
    for i, r in enumerate(sign_ranges_m):
        check_positive("sign_ranges_m", r)
        half = max(2, int(round(0.6 / r / ifov)))
        half = min(half, height // 3, width // (2 * n + 1))
        c = int((i + 0.5) * width / n)
        rs = slice(height // 2 - half, height // 2 + half)
        cs = slice(c - half, c + half)
        rng_m[rs, cs] = r
        refl[rs, cs] = 0.6
        ra[rs, cs] = sign_retro_per_sr
    return ActiveScene(
        range_m=rng_m,
        reflectance=refl,
        retro_coefficient_per_sr=ra,
        medium=Medium.from_visibility(visibility_m, name=f"fog, V = {visibility_m:g} m"),
        ambient_lux=ambient_lux,
        name="signs in fog",
    )


def depth_scene(
    height: int = 64,
    width: int = 96,
    camera_height_m: float = 1.5,
    near_ground_m: float = 40.0,
    ambient_lux: float = 1.0,
    visibility_m: float = 20e3,
    ifov_rad: float | None = None,
) -> ActiveScene:
    """A scene with real depth for gate sweeps: a test range seen close up.

    Flat ground (ρ = 0.2) seen from ``camera_height_m``, the camera tilted down so that the
    bottom row sees the ground at ``near_ground_m`` (range = h / tan(depression) per row);
    three Lambertian boards standing on the ground (0.30 × 0.25 m, ρ = 0.35, 0.8, 0.5 at
    45, 52 and 58 m) and two retroreflectors on the ground at 48 m and 62 m.

    Why so close: with the default 25 mm lens the pixel sees 0.22 mrad (1 cm at 45 m), and
    a 200 W, 135 ns pulse spread over the full-sensor field gives a ρ = 0.35 surface only
    0.027 e⁻ per pulse at 240 m, below the 12 e⁻ read noise even after 291 pulses (the most
    that fit a 25 Hz frame); at 45–60 m it gives ≈ 0.5 e⁻ per pulse. Retroreflectors (the
    seed's targets) are visible much farther.

    Parameters
    ----------
    height, width : int
        Size, pixels.
    camera_height_m : float
        Height of the camera above the ground, m.
    near_ground_m : float
        Range of the ground seen by the bottom row, m.
    ambient_lux : float
        Ambient illuminance, lux.
    visibility_m : float
        Meteorological visibility of the air, m.
    ifov_rad : float, optional
        Angle one pixel sees, rad (default: the gated camera's lens and pitch).

    Returns
    -------
    ActiveScene
        The scene, with a range per pixel.
    """
    check_int("height", height, 16)
    check_int("width", width, 16)
    check_positive("camera_height_m", camera_height_m)
    check_positive("near_ground_m", near_ground_m)
    ifov = ifov_rad or ActiveImagingGeometry().ifov_rad
    bottom_angle = math.atan(camera_height_m / near_ground_m)
    # depression angle of each row's centre (row height-1 is the bottom row)
    angle = bottom_angle - (height - 1 - np.arange(height)) * ifov
    with np.errstate(divide="ignore"):
        ground = np.where(angle > 0, camera_height_m / np.tan(np.maximum(angle, 1e-12)), np.inf)
    rng = np.repeat(ground[:, None], width, axis=1)
    refl = np.where(np.isfinite(rng), 0.2, 0.0)

    def board(range_m, col_frac, width_m, height_m, rho):
        foot = int(np.argmin(np.abs(np.where(np.isfinite(ground), ground, 1e30) - range_m)))
        half_w = max(1, int(round(width_m / 2 / range_m / ifov)))
        h_px = max(1, int(round(height_m / range_m / ifov)))
        c = int(col_frac * width)
        rs, cs = slice(max(0, foot - h_px), foot + 1), slice(max(0, c - half_w), min(width, c + half_w))
        rng[rs, cs] = range_m
        refl[rs, cs] = rho
        return foot

    board(58.0, 0.78, 0.30, 0.25, 0.5)
    board(52.0, 0.50, 0.30, 0.25, 0.8)
    board(45.0, 0.22, 0.30, 0.25, 0.35)
    retros = []
    for r, c in ((48.0, 0.06), (62.0, 0.94)):
        foot = int(np.argmin(np.abs(np.where(np.isfinite(ground), ground, 1e30) - r)))
        retros.append(PointRetroreflector(range_m=r, row=float(foot), col=c * width, label=f"{r:g} m",
                                          divergence_half_angle_rad=math.radians(1.5)))
    return ActiveScene(range_m=rng, reflectance=refl, retroreflectors=retros,
                       medium=Medium.from_visibility(visibility_m), ambient_lux=ambient_lux,
                       name="test range: ground, boards and reflectors")
