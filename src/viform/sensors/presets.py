"""The physics of the seed-001 presets (the 5T pixel, its intensity unit, the segment timings).

The presets themselves — every sensor by name, built with its parameters — are the catalogue's
(:mod:`viform.sensors.catalog`); this module holds what seed 001 fixes and how it was fitted.

Seed 001 parameter set (documented in docs/frame-sensors.md)
-------------------------------------------------------------
The seed reports light intensity without a unit, and its two experiments saturate the
normal mode at different intensities (30 in fig. 8, 35 in fig. 9). One *seed intensity
unit* is therefore calibrated per figure so that the normal mode saturates where the seed
measured it (:data:`PAPER001_FIG8_UNIT_LUX`, :data:`PAPER001_FIG9_UNIT_LUX`); every other
figure then follows from the segment times and barriers. The DN axis: the normal mode
gives 374 DN at intensity 15 (fig. 8), so the full well spans 748 DN (10-bit ADC, fig. 7).

* Two segments (fig. 8): the knee must lie at intensity 15 / 374 DN and the saturation at
  105. With T = T1 + T2 = 130 µs and barrier B1: knee B1/T1 = 15 units, saturation
  (FW − B1)/T2 = 105 units, FW/T = 30 units ⇒ T1/T = 5/6, B1 = 5/12·FW. The seed's
  label "8/8" (segmented time = whole exposure) cannot be taken literally: with no
  final segment the output would stop at the barrier; we read it as the largest ratio.
* Three segments (fig. 9): knees at 348 DN and 669.8 DN and a 12.57× extension (35 → 440)
  are met by T1 : T2 : T3 = 0.74 : 0.25 : 0.01 of 130 µs and B1 = 0.344·FW,
  B2 = 0.874·FW (solved from the knee equations in :mod:`viform.sensors.segmented`).
"""

from __future__ import annotations

from viform.light.radiometry import PixelOptics
from viform.sensors.frame import FramePixelParameters

#: Seed 001 total exposure, s (fig. 8: "总曝光时间为 130 us").
PAPER001_EXPOSURE_S = 130e-6
#: Seed 001 full well of our 5T pixel model, e⁻ (not given by the seed).
PAPER001_FULL_WELL_E = 10_000.0
#: DN above black at full well (fig. 8: 374 DN at half the normal-mode saturation).
PAPER001_FULL_SCALE_DN = 748.0
#: Two-segment (fig. 8) timing and barrier.
PAPER001_2SEG_FRACTIONS = (5 / 6, 1 / 6)
PAPER001_2SEG_BARRIERS_FW = (5 / 12,)
#: Three-segment (fig. 9) timing and barriers.
PAPER001_3SEG_FRACTIONS = (0.74, 0.25, 0.01)
PAPER001_3SEG_BARRIERS_FW = (0.344, 0.874)


def paper001_pixel_parameters(**overrides) -> FramePixelParameters:
    """Seed 001's 5T global-shutter pixel: 3.42 µm pitch (seed 001 §3.1), 10-bit readout.

    Conversion gain 60 µV/e⁻ and an ADC range chosen so the full well spans 748 DN
    (K = 0.0748 DN/e⁻). QE, noise and dark current are typical values (not in the seed).
    """
    cg = 60e-6
    kw = dict(
        optics=PixelOptics(pixel_pitch_m=3.42e-6, fill_factor=1.0, quantum_efficiency=0.6),
        full_well_electrons=PAPER001_FULL_WELL_E,
        conversion_gain_v_per_e=cg,
        read_noise_electrons=3.0,
        dark_current_e_per_s=20.0,
        dsnu_electrons=1.0,
        prnu_fraction=0.01,
        analog_gain=1.0,
        adc_bits=10,
        black_offset_dn=16.0,
        adc_range_v=cg * 1023 * PAPER001_FULL_WELL_E / PAPER001_FULL_SCALE_DN,
    )
    kw.update(overrides)
    return FramePixelParameters(**kw)


def paper001_unit_lux(normal_saturation_units: float) -> float:
    """Lux of one seed-001 intensity unit such that the normal mode saturates at the given value."""
    p = paper001_pixel_parameters()
    rate = p.full_well_electrons / PAPER001_EXPOSURE_S - p.dark_current_e_per_s
    return rate / p.optics.electrons_per_lux_second / normal_saturation_units


#: One seed-001 intensity unit in lux, fig. 8 (normal mode saturates at 30).
PAPER001_FIG8_UNIT_LUX = paper001_unit_lux(30.0)
#: One seed-001 intensity unit in lux, fig. 9 (normal mode saturates at 35).
PAPER001_FIG9_UNIT_LUX = paper001_unit_lux(35.0)
