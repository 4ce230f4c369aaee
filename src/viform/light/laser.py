"""Emitter and receiver of a range-gated active imager (seed 004).

Seed 004 (experimental section): the illuminator was a PerkinElmer QPGAS2S09H pulsed
semiconductor laser, 905 nm, 200 W peak output, 120–150 ns pulses at 10–15 kHz. The
defaults below take the middle of each range (135 ns, 12.5 kHz).

The receiver is a lens of focal length ``f`` and f-number ``N`` (aperture D = f/N) in
front of the CCD, behind a band-pass filter centred on the laser line. The seed gives no
lens, beam-divergence or filter data; the defaults here are assumptions, stated in
``docs/range-gated.md``:

* f = 25 mm, f/1.4 (a common C-mount lens for a 1/4-type CCD; FOV ≈ 8.4° × 6.3° on
  the ICX618's 659 × 494 pixels of 5.6 µm);
* optics transmission 0.8 (lens × filter at the laser line);
* filter FWHM 50 nm around 905 nm (an uncooled 905 nm diode drifts ≈ 0.25 nm/K, so
  practical filters are 30–60 nm wide);
* the beam divergence is matched to the receiver's field of view (top-hat beam filling
  exactly the full-sensor FOV), as the issue asks.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from viform._validate import ViformError, check_positive, check_range
from viform.light.radiometry import SPEED_OF_LIGHT_M_PER_S, photon_energy_j

#: Allowed lens f-numbers: from the limit of a lens in air (N = 1/(2·NA) ≥ 0.5) to a pinhole-like f/64.
F_NUMBER_RANGE = (0.5, 64.0)

#: Laser wavelength of the seed's emitter, m (seed 004: 905 nm).
LASER_WAVELENGTH_M = 905e-9


@dataclass(frozen=True)
class PulsedLaser:
    """A pulsed laser diode with a rectangular pulse (seed 004, experimental section).

    Attributes
    ----------
    peak_power_w : float
        Peak optical output power, W (seed: 200 W).
    pulse_width_s : float
        Pulse duration (rectangular model), s (seed: 120–150 ns).
    repetition_hz : float
        Pulse repetition frequency, Hz (seed: 10–15 kHz).
    wavelength_m : float
        Emission wavelength, m (seed: 905 nm).
    transmitter_efficiency : float
        Fraction of the output that leaves the beam-shaping optics, (0, 1].
    divergence_x_rad, divergence_y_rad : float or None
        Full beam divergence (top-hat), rad; None = matched to the receiver FOV.
    """

    peak_power_w: float = 200.0
    pulse_width_s: float = 135e-9
    repetition_hz: float = 12.5e3
    wavelength_m: float = LASER_WAVELENGTH_M
    transmitter_efficiency: float = 0.8
    divergence_x_rad: float | None = None
    divergence_y_rad: float | None = None

    def __post_init__(self):
        check_positive("peak_power_w", self.peak_power_w)
        check_positive("pulse_width_s", self.pulse_width_s)
        check_positive("repetition_hz", self.repetition_hz)
        check_positive("wavelength_m", self.wavelength_m)
        check_range("transmitter_efficiency", self.transmitter_efficiency, 0.0, 1.0, low_open=True)
        for name in ("divergence_x_rad", "divergence_y_rad"):
            value = getattr(self, name)
            if value is not None:
                check_range(name, value, 0.0, math.pi, low_open=True)
        if self.pulse_width_s >= 1.0 / self.repetition_hz:
            raise ViformError(
                f"pulse_width_s = {self.pulse_width_s!r} must be shorter than the pulse "
                f"period 1/repetition_hz = {1.0 / self.repetition_hz:g} s"
            )

    @property
    def period_s(self) -> float:
        """Time between pulses, s."""
        return 1.0 / self.repetition_hz

    @property
    def pulse_energy_j(self) -> float:
        """Optical energy leaving the transmitter per pulse, J (P·τ·η_tx)."""
        return self.peak_power_w * self.pulse_width_s * self.transmitter_efficiency

    @property
    def photons_per_pulse(self) -> float:
        """Photons leaving the transmitter per pulse."""
        return self.pulse_energy_j / photon_energy_j(self.wavelength_m)

    @property
    def unambiguous_range_m(self) -> float:
        """c / (2 f_rep): beyond it a return arrives after the next pulse has left, m."""
        return SPEED_OF_LIGHT_M_PER_S / (2.0 * self.repetition_hz)

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(pulse_energy_j=self.pulse_energy_j, unambiguous_range_m=self.unambiguous_range_m)
        return d


@dataclass(frozen=True)
class Receiver:
    """Receiver optics: lens, band-pass filter, biaxial overlap.

    Attributes
    ----------
    focal_length_m : float
        Lens focal length, m.
    f_number : float
        Lens f-number N (aperture diameter D = f/N).
    transmission : float
        Lens × filter transmission at the laser line, (0, 1].
    filter_center_m, filter_bandwidth_m : float
        Band-pass filter centre and full width, m. Ambient (sun) light is counted only in
        this band: lux says nothing about 905 nm, see :func:`viform.light.active.solar_band_irradiance_w_per_m2`.
    overlap_range_m : float
        Scale of the laser/receiver overlap function O(r) = 1 − exp(−(r/r_o)²) of a
        biaxial layout: the near-field fog in front of the lens is only partly seen.
    """

    focal_length_m: float = 25e-3
    f_number: float = 1.4
    transmission: float = 0.8
    filter_center_m: float = LASER_WAVELENGTH_M
    filter_bandwidth_m: float = 50e-9
    overlap_range_m: float = 3.0

    def __post_init__(self):
        check_positive("focal_length_m", self.focal_length_m)
        check_range("f_number", self.f_number, *F_NUMBER_RANGE)
        check_range("transmission", self.transmission, 0.0, 1.0, low_open=True)
        check_positive("filter_center_m", self.filter_center_m)
        check_positive("filter_bandwidth_m", self.filter_bandwidth_m)
        check_positive("overlap_range_m", self.overlap_range_m)

    @property
    def aperture_diameter_m(self) -> float:
        return self.focal_length_m / self.f_number

    @property
    def aperture_area_m2(self) -> float:
        return math.pi * self.aperture_diameter_m**2 / 4.0

    def ifov_rad(self, pixel_pitch_m: float) -> float:
        """Instantaneous field of view of one pixel, rad (small angle)."""
        return check_positive("pixel_pitch_m", pixel_pitch_m) / self.focal_length_m

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(aperture_diameter_m=self.aperture_diameter_m)
        return d


def round_trip_time_s(range_m):
    """Time for light to reach ``range_m`` and come back, 2R/c (seed 004, Fig. 3: t_откл)."""
    import numpy as np

    r = np.asarray(range_m, dtype=np.float64)
    if np.any(r < 0):
        raise ViformError(f"range_m = {range_m!r} is not allowed: ranges must be ≥ 0 m")
    out = 2.0 * r / SPEED_OF_LIGHT_M_PER_S
    return float(out) if out.ndim == 0 else out


def range_from_delay_m(delay_s):
    """Inverse of :func:`round_trip_time_s`: R = c·t/2."""
    import numpy as np

    out = np.asarray(delay_s, dtype=np.float64) * SPEED_OF_LIGHT_M_PER_S / 2.0
    return float(out) if out.ndim == 0 else out
