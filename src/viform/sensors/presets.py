"""Built-in sensor presets named after the seeds (``viform characterize NAME``).

=====================  ===========================================================
name                   sensor
=====================  ===========================================================
``cmos``               conventional global-shutter CMOS (seed 000 §2, timed mode)
``seed001-normal``     seed 001's 5T pixel in normal mode (130 µs exposure)
``seed001-2seg``       seed 001 fig. 8, two segments (the "8/8" case)
``seed001-3seg``       seed 001 fig. 9, three segments
``seed003-4t``         seed 003's reference plain 4T APS (33.33 ms integration)
``seed003-overflow``   seed 003's conditional-overflow triple-integration pixel
``seed003-overflow-ktc``  the same with the readout's reset (kTC) noise
``seed003-lofic``      seed 003 fig. 5(b): lateral-overflow capacitor pixel (DR_b baseline)
``spike``              seed 000's spike camera (Q = 100 e⁻, 40 kHz), if
                       :mod:`viform.sensors.spike` is installed
=====================  ===========================================================

Seed 001 parameter set (documented in docs/frame-sensors.md)
-------------------------------------------------------------
The seed reports light intensity without a unit, and its two experiments saturate the
normal mode at different intensities (30 in fig. 8, 35 in fig. 9). One *seed intensity
unit* is therefore calibrated per figure so that the normal mode saturates where the seed
measured it (:data:`SEED001_FIG8_UNIT_LUX`, :data:`SEED001_FIG9_UNIT_LUX`); every other
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

from collections.abc import Callable
from dataclasses import fields

from viform._validate import ViformError, check_choice
from viform.light.radiometry import PixelOptics
from viform.sensors.frame import FramePixelParameters, FrameSensor
from viform.sensors.overflow import OverflowSensor, lofic_pixel_parameters, seed003_pixel_parameters
from viform.sensors.segmented import SegmentedExposureSensor

#: Seed 001 total exposure, s (fig. 8: "总曝光时间为 130 us").
SEED001_EXPOSURE_S = 130e-6
#: Seed 001 full well of our 5T pixel model, e⁻ (not given by the seed).
SEED001_FULL_WELL_E = 10_000.0
#: DN above black at full well (fig. 8: 374 DN at half the normal-mode saturation).
SEED001_FULL_SCALE_DN = 748.0
#: Two-segment (fig. 8) timing and barrier.
SEED001_2SEG_FRACTIONS = (5 / 6, 1 / 6)
SEED001_2SEG_BARRIERS_FW = (5 / 12,)
#: Three-segment (fig. 9) timing and barriers.
SEED001_3SEG_FRACTIONS = (0.74, 0.25, 0.01)
SEED001_3SEG_BARRIERS_FW = (0.344, 0.874)


def seed001_pixel_parameters(**overrides) -> FramePixelParameters:
    """Seed 001's 5T global-shutter pixel: 3.42 µm pitch (seed 001 §3.1), 10-bit readout.

    Conversion gain 60 µV/e⁻ and an ADC range chosen so the full well spans 748 DN
    (K = 0.0748 DN/e⁻). QE, noise and dark current are typical values (not in the seed).
    """
    cg = 60e-6
    kw = dict(
        optics=PixelOptics(pixel_pitch_m=3.42e-6, fill_factor=1.0, quantum_efficiency=0.6),
        full_well_electrons=SEED001_FULL_WELL_E,
        conversion_gain_v_per_e=cg,
        read_noise_electrons=3.0,
        dark_current_e_per_s=20.0,
        dsnu_electrons=1.0,
        prnu_fraction=0.01,
        analog_gain=1.0,
        adc_bits=10,
        black_offset_dn=16.0,
        adc_range_v=cg * 1023 * SEED001_FULL_WELL_E / SEED001_FULL_SCALE_DN,
    )
    kw.update(overrides)
    return FramePixelParameters(**kw)


def seed001_unit_lux(normal_saturation_units: float) -> float:
    """Lux of one seed-001 intensity unit such that the normal mode saturates at the given value."""
    p = seed001_pixel_parameters()
    rate = p.full_well_electrons / SEED001_EXPOSURE_S - p.dark_current_e_per_s
    return rate / p.optics.electrons_per_lux_second / normal_saturation_units


#: One seed-001 intensity unit in lux, fig. 8 (normal mode saturates at 30).
SEED001_FIG8_UNIT_LUX = seed001_unit_lux(30.0)
#: One seed-001 intensity unit in lux, fig. 9 (normal mode saturates at 35).
SEED001_FIG9_UNIT_LUX = seed001_unit_lux(35.0)


def _seed001_segmented(fractions, barriers_fw, pixel=None, **kw) -> SegmentedExposureSensor:
    fw = SEED001_FULL_WELL_E
    return SegmentedExposureSensor(
        seed001_pixel_parameters(**(pixel or {})),
        [f * SEED001_EXPOSURE_S for f in fractions],
        [b * fw for b in barriers_fw],
        frame_rate_hz=60.0,
        **kw,
    )


def _spike(**kw):
    from viform.sensors.spike import SpikeSensor, SpikeSensorParameters  # noqa: F401 - optional module

    return SpikeSensor(
        SpikeSensorParameters(optics=PixelOptics(pixel_pitch_m=10e-6, quantum_efficiency=0.7)), **kw
    )


PRESETS: dict[str, tuple[str, Callable]] = {
    "cmos": (
        "conventional global-shutter CMOS, 10 ms exposure at 30 fps",
        lambda pixel=None, **kw: FrameSensor(
            FramePixelParameters(**(pixel or {})), exposure_s=10e-3, frame_rate_hz=30.0, **kw
        ),
    ),
    "seed001-normal": (
        "5T global-shutter pixel, normal mode, 130 µs exposure",
        lambda pixel=None, **kw: FrameSensor(
            seed001_pixel_parameters(**(pixel or {})), exposure_s=SEED001_EXPOSURE_S, frame_rate_hz=60.0, **kw
        ),
    ),
    "seed001-2seg": (
        "segmented exposure, two segments (T1:T2 = 5:1, barrier 5/12 of the full well)",
        lambda **kw: _seed001_segmented(SEED001_2SEG_FRACTIONS, SEED001_2SEG_BARRIERS_FW, **kw),
    ),
    "seed001-3seg": (
        "segmented exposure, three segments (0.74:0.25:0.01, barriers 0.344/0.874 of the full well)",
        lambda **kw: _seed001_segmented(SEED001_3SEG_FRACTIONS, SEED001_3SEG_BARRIERS_FW, **kw),
    ),
    "seed003-4t": (
        "plain 4T APS, 33.33 ms integration at 30 fps",
        lambda pixel=None, **kw: FrameSensor(
            seed003_pixel_parameters(**(pixel or {})),
            exposure_s=sum((32.8e-3, 0.5e-3, 0.03e-3)),
            frame_rate_hz=30.0,
            **kw,
        ),
    ),
    "seed003-overflow": (
        "conditional-overflow pixel, C_F = 500 fF, integration 32.8/0.5/0.03 ms at 30 fps",
        lambda pixel=None, **kw: OverflowSensor(seed003_pixel_parameters(**(pixel or {})), **kw),
    ),
    "seed003-overflow-ktc": (
        "conditional-overflow pixel with the readout's reset (kTC) noise (120 e- per reset)",
        lambda pixel=None, **kw: OverflowSensor(seed003_pixel_parameters(**(pixel or {})), ktc_noise=True, **kw),
    ),
    "seed003-lofic": (
        "lateral-overflow capacitor pixel, C_S = 500 fF read with the photodiode "
        "at low gain, 33.33 ms at 30 fps",
        lambda pixel=None, **kw: FrameSensor(
            lofic_pixel_parameters(**(pixel or {})),
            exposure_s=sum((32.8e-3, 0.5e-3, 0.03e-3)),
            frame_rate_hz=30.0,
            **kw,
        ),
    ),
}


def spike_available() -> bool:
    """Whether :mod:`viform.sensors.spike` (the spike camera) is installed in this tree."""
    try:
        import viform.sensors.spike  # noqa: F401
    except ImportError:
        return False
    return True


def preset_names() -> list[str]:
    """Names accepted by :func:`make_sensor` (``spike`` only when the spike module exists)."""
    return list(PRESETS) + (["spike", *_spike_chip_names()] if spike_available() else [])


def _spike_chip_names() -> list[str]:
    """The real-chip spike presets (:mod:`viform.sensors.spike_presets`)."""
    from viform.sensors.spike_presets import SPIKE_PRESET_NAMES

    return list(SPIKE_PRESET_NAMES)


#: Pixel fields any frame preset takes by name (``make_sensor("seed001-2seg", readout_time_s=…)``).
PIXEL_FIELDS = tuple(f.name for f in fields(FramePixelParameters))


def make_sensor(name: str, **kwargs):
    """Build the preset sensor ``name``.

    Keyword arguments are fields by name: a :class:`FramePixelParameters` field (e.g.
    ``read_noise_electrons``, ``parasitic_light_sensitivity``, ``black_sun_fraction``) replaces
    the preset pixel's value; anything else goes to the sensor's constructor (e.g.
    ``comparator_noise_v`` of the overflow pixel, ``clamp_noise_electrons`` of the segmented
    one). So a design sweep can vary any parameter by its name.
    """
    check_choice("sensor", name, preset_names())
    if name == "spike":
        return _spike(**kwargs)
    if name in _spike_chip_names():
        from viform.sensors.spike_presets import load_spike_preset

        return load_spike_preset(name).sensor(**kwargs)
    pixel = {k: kwargs.pop(k) for k in list(kwargs) if k in PIXEL_FIELDS}
    try:
        return PRESETS[name][1](pixel=pixel or None, **kwargs)
    except TypeError as exc:
        raise ViformError(f"preset {name!r} does not accept these options: {exc}") from None


def preset_fields(name: str) -> list[str]:
    """Every parameter name :func:`make_sensor` accepts for the frame preset ``name``."""
    import inspect

    check_choice("sensor", name, list(PRESETS))
    sensor = PRESETS[name][1]()
    ctor = [p for p in inspect.signature(type(sensor).__init__).parameters if p not in ("self", "parameters")]
    return sorted(set(PIXEL_FIELDS) - {"optics"}) + sorted(ctor)


def describe_preset(name: str) -> str:
    check_choice("sensor", name, preset_names())
    if name in _spike_chip_names():
        from viform.sensors.spike_presets import describe_spike_preset

        return describe_spike_preset(name)
    return "spike camera (Q = 100 e⁻, 40 kHz)" if name == "spike" else PRESETS[name][0]
