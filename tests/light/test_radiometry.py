"""Radiometry against seed 000 §4.3: 1e5 lux on 100 µm² ≈ 4.09e10 photons/s; Q = 100 at QE 0.7 → ≈ 3.5 ns."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.radiometry import (
    PixelOptics,
    lux_to_photons_per_s,
    photon_energy_j,
    time_to_threshold_s,
)


def test_seed_000_photons_per_second_at_noon_sun():
    photons = float(lux_to_photons_per_s(1e5, 100e-12))
    assert photons == pytest.approx(4.09e10, rel=2e-3)


def test_seed_000_strongest_light_spike_width():
    optics = PixelOptics(pixel_pitch_m=10e-6, quantum_efficiency=0.7)
    assert time_to_threshold_s(100, 1e5, optics) == pytest.approx(3.5e-9, rel=0.01)


def test_photon_energy_at_555_nm():
    # h·c/λ = 3.579e-19 J
    assert photon_energy_j(555e-9) == pytest.approx(3.5793e-19, rel=1e-4)


def test_fill_factor_and_qe_scale_linearly():
    full = PixelOptics(pixel_pitch_m=5e-6, fill_factor=1.0, quantum_efficiency=1.0)
    half = PixelOptics(pixel_pitch_m=5e-6, fill_factor=0.5, quantum_efficiency=0.6)
    assert half.electrons_per_lux_second == pytest.approx(0.3 * full.electrons_per_lux_second)
    lux = np.array([0.0, 1.0, 1e3])
    assert np.allclose(half.lux_from_electrons_per_s(half.electrons_per_s(lux)), lux)


@pytest.mark.parametrize("bad", [np.nan, -1.0, np.inf])
def test_bad_lux_is_refused_with_the_parameter_named(bad):
    with pytest.raises(ViformError, match="lux"):
        lux_to_photons_per_s(np.array([1.0, bad]), 1e-10)


@pytest.mark.parametrize("field,value", [("pixel_pitch_m", 0.0), ("fill_factor", 1.5), ("quantum_efficiency", 0.0)])
def test_bad_optics_names_the_parameter(field, value):
    with pytest.raises(ViformError, match=field):
        PixelOptics(**{field: value})
