"""Radiometry: from illuminance in lux to photons and photoelectrons per second per pixel.

Photometric units weight radiant power by the eye's luminous efficiency; at the photopic
peak (555 nm, strictly 540 THz) 1 W of radiant flux is 683 lm (SI definition of the
candela). A scene described in lux is therefore converted to photon flux through an
*equivalent monochromatic wavelength*: 555 nm by default, as in seed 000 §4.3.

Seed 000 §4.3: 1e5 lux on a 100 µm² pixel gives about 4.09e10 photons/s; with a quantum
efficiency of 0.7 a threshold of Q = 100 electrons is reached in about 3.5 ns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_positive, check_range

#: Planck constant, J·s (SI 2019, exact).
PLANCK_J_S = 6.62607015e-34
#: Speed of light in vacuum, m/s (exact).
SPEED_OF_LIGHT_M_PER_S = 299_792_458.0
#: Elementary charge, C (exact).
ELEMENTARY_CHARGE_C = 1.602176634e-19
#: Luminous efficacy of 540 THz radiation, lm/W (SI definition of the candela).
LUMINOUS_EFFICACY_LM_PER_W = 683.0
#: Default equivalent wavelength for lux → photons, m (photopic peak, seed 000 §4.3).
PHOTOPIC_WAVELENGTH_M = 555e-9


def photon_energy_j(wavelength_m: float = PHOTOPIC_WAVELENGTH_M) -> float:
    """Energy of one photon, E = h·c/λ, in joules.

    Parameters
    ----------
    wavelength_m : float
        Wavelength, m (default 555 nm, the photopic peak).

    Returns
    -------
    float
        Photon energy, J.

    Examples
    --------
    >>> f"{photon_energy_j(555e-9):.4g} J"
    '3.579e-19 J'
    """
    check_positive("wavelength_m", wavelength_m)
    return PLANCK_J_S * SPEED_OF_LIGHT_M_PER_S / wavelength_m


def lux_to_irradiance_w_per_m2(lux, wavelength_m: float = PHOTOPIC_WAVELENGTH_M,
                               luminous_efficiency: float = 1.0):
    """Irradiance (W/m²) of monochromatic light of the given illuminance (lux).

    E_e = E_v / (683 lm/W · V(λ)); ``luminous_efficiency`` is V(λ) (1 at 555 nm).
    """
    check_range("luminous_efficiency", luminous_efficiency, 0.0, 1.0, low_open=True)
    return np.asarray(lux, dtype=np.float64) / (LUMINOUS_EFFICACY_LM_PER_W * luminous_efficiency)


def photon_flux_density_per_lux(wavelength_m: float = PHOTOPIC_WAVELENGTH_M,
                                luminous_efficiency: float = 1.0) -> float:
    """Photons per second per m² per lux (≈ 4.09e15 at 555 nm)."""
    return float(lux_to_irradiance_w_per_m2(1.0, wavelength_m, luminous_efficiency)) / photon_energy_j(
        wavelength_m)


def lux_to_photons_per_s(lux, pixel_area_m2: float, fill_factor: float = 1.0,
                         wavelength_m: float = PHOTOPIC_WAVELENGTH_M,
                         luminous_efficiency: float = 1.0):
    """Photons per second reaching the photosensitive part of one pixel.

    Parameters
    ----------
    lux : array_like
        Illuminance on the sensor plane, lux (lm/m²). Must be finite and ≥ 0.
    pixel_area_m2 : float
        Pixel area, m² (pitch²).
    fill_factor : float
        Photosensitive fraction of the pixel area, in (0, 1].
    wavelength_m : float
        Equivalent monochromatic wavelength, m.
    luminous_efficiency : float
        Luminous efficiency of the light's spectrum relative to 555 nm, in (0, 1].

    Returns
    -------
    ndarray of float64
        Photon rate per pixel, photons/s, the shape of ``lux``.

    Examples
    --------
    Seed 000 §4.3: 1e5 lux on 100 µm².

    >>> round(float(lux_to_photons_per_s(1e5, 100e-12)) / 1e10, 2)
    4.09
    """
    check_positive("pixel_area_m2", pixel_area_m2)
    check_range("fill_factor", fill_factor, 0.0, 1.0, low_open=True)
    lux = check_lux(lux)
    return lux * (pixel_area_m2 * fill_factor * photon_flux_density_per_lux(wavelength_m,
                                                                            luminous_efficiency))


def check_lux(lux, name: str = "lux"):
    """Return ``lux`` as float64, refusing NaN, infinities and negative values."""
    arr = np.asarray(lux, dtype=np.float64)
    if arr.size and not np.all(np.isfinite(arr)):
        raise ViformError(f"{name} contains NaN or infinite values; illuminance must be finite lux ≥ 0")
    if arr.size and float(arr.min()) < 0:
        raise ViformError(f"{name} has a negative value ({float(arr.min()):g}); illuminance must be ≥ 0 lux")
    return arr


@dataclass(frozen=True)
class PixelOptics:
    """How light on the sensor plane becomes photoelectrons in one pixel.

    Attributes
    ----------
    pixel_pitch_m : float
        Pixel pitch, m (square pixels; area = pitch²).
    fill_factor : float
        Photosensitive fraction of the pixel, (0, 1].
    quantum_efficiency : float
        Photoelectrons per incident photon, (0, 1].
    wavelength_m : float
        Equivalent wavelength for the lux → photon conversion, m.
    """

    pixel_pitch_m: float = 10e-6
    fill_factor: float = 1.0
    quantum_efficiency: float = 0.7
    wavelength_m: float = PHOTOPIC_WAVELENGTH_M

    def __post_init__(self):
        check_positive("pixel_pitch_m", self.pixel_pitch_m)
        check_range("fill_factor", self.fill_factor, 0.0, 1.0, low_open=True)
        check_range("quantum_efficiency", self.quantum_efficiency, 0.0, 1.0, low_open=True)
        check_positive("wavelength_m", self.wavelength_m)

    @property
    def pixel_area_m2(self) -> float:
        return self.pixel_pitch_m ** 2

    @property
    def electrons_per_lux_second(self) -> float:
        """Photoelectrons per second per lux in one pixel."""
        return float(lux_to_photons_per_s(1.0, self.pixel_area_m2, self.fill_factor,
                                          self.wavelength_m)) * self.quantum_efficiency

    def photons_per_s(self, lux):
        """Incident photons per second for illuminance ``lux``."""
        return lux_to_photons_per_s(lux, self.pixel_area_m2, self.fill_factor, self.wavelength_m)

    def electrons_per_s(self, lux):
        """Photoelectron rate (e⁻/s, signal only) for illuminance ``lux``."""
        return check_lux(lux) * self.electrons_per_lux_second

    def lux_from_electrons_per_s(self, electrons_per_s):
        """Illuminance (lux) that gives the signal photoelectron rate ``electrons_per_s``."""
        return np.asarray(electrons_per_s, dtype=np.float64) / self.electrons_per_lux_second


def time_to_threshold_s(threshold_electrons: float, lux: float, optics: PixelOptics) -> float:
    """Mean time to collect ``threshold_electrons`` at illuminance ``lux`` (seed 000 §4.3, τ = Q/(Φ·η)).

    >>> optics = PixelOptics(pixel_pitch_m=10e-6, quantum_efficiency=0.7)
    >>> round(time_to_threshold_s(100, 1e5, optics) * 1e9, 1)
    3.5
    """
    check_positive("threshold_electrons", threshold_electrons)
    rate = float(optics.electrons_per_s(lux))
    check_positive("lux", lux)
    return threshold_electrons / rate
