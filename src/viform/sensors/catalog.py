"""Every sensor viform simulates, by name: the one catalogue behind every command.

An entry (:class:`SensorEntry`) holds a sensor's name, label, one-line description and family,
the parameters it accepts (:class:`Parameter`: unit, default, allowed range) and ``build(**settings)``,
which returns a :class:`~viform.sensors.base.Sensor` whose ``capture`` gives the sensor's native
output. ``capture``, ``compare``, ``sweep``, ``characterize``, ``dataset``, ``gated``, ``highspeed``
and every help text list and build sensors from :data:`SENSORS` alone.

=====================  ==========  ===============================================================
name                   family      sensor
=====================  ==========  ===============================================================
``spike``              spike       seed 000's worked example: Q = 100 e⁻, 40 kHz (the scene's size)
``spikeone``           spike       the SpikeOne chip, 400×250 at 40 kHz, Q = 16 250 e⁻
``spiketwo``           spike       the SpikeTwo chip, 1000×1000 at 20 kHz
``spiketwo-40k``       spike       the SpikeTwo chip in its 40 kHz mode
``cmos-short``         frame       conventional CMOS, 1 ms at 30 fps
``cmos``               frame       conventional CMOS, 10 ms at 30 fps
``seed001-normal``     frame       seed 001's 5T pixel, normal mode, 130 µs
``seed001-2seg``       segmented   seed 001 fig. 8, two segments
``seed001-3seg``       segmented   seed 001 fig. 9, three segments
``seed003-4t``         frame       seed 003's plain 4T APS, 33.33 ms
``seed003-overflow``   overflow    seed 003's conditional-overflow pixel
``seed003-overflow-ktc``  overflow  the same with the readout's reset (kTC) noise
``seed003-lofic``      frame       seed 003 fig. 5(b): lateral-overflow capacitor pixel
``highspeed``          highspeed   seed 002's LUX13HS-like camera, 1 667 fps, auto-exposure
``gated``              gated       seed 004's range-gated interline CCD with its 905 nm laser
=====================  ==========  ===============================================================

Parameters are reached by name: a field of the pixel (:class:`~viform.sensors.frame.FramePixelParameters`,
:class:`~viform.sensors.spike.SpikeSensorParameters`), of its optics
(:class:`~viform.light.radiometry.PixelOptics`), of the gated CCD, its laser (``laser_*``) and receiver
(``receiver_*``), an argument of the camera (exposure, frame rate, …), or a shorthand that sets
several at once (``threshold_level``: a spike chip's 16 threshold levels; ``exposure_s`` of a
segmented pixel: every segment scaled, ratios kept; the overflow pixel's three integration times).
Adding a sensor is one entry here plus its model's module (docs/CONTRIBUTING.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from viform._validate import ViformError, check_positive
from viform.light.laser import PulsedLaser, Receiver
from viform.light.radiometry import PixelOptics
from viform.sensors import presets
from viform.sensors.base import Sensor
from viform.sensors.frame import FramePixelParameters, FrameSensor
from viform.sensors.gated_ccd import MODES, GatedInterlineCCD, InterlineCCDParameters, interline_ccd_parameters
from viform.sensors.highspeed import HighSpeedCamera, lux13hs_pixel_parameters
from viform.sensors.overflow import (
    PAPER003_INTEGRATIONS_S,
    OverflowSensor,
    lofic_pixel_parameters,
    paper003_pixel_parameters,
)
from viform.sensors.parameters import (
    Parameter,
    arguments_of,
    fields_of,
    merged,
    parameter_for,
)
from viform.sensors.segmented import SegmentedExposureSensor
from viform.sensors.spike import SpikeSensor, SpikeSensorParameters
from viform.sensors.spike_presets import (
    N_THRESHOLD_LEVELS,
    SPIKE_PRESET_NAMES,
    load_spike_preset,
    threshold_level_electrons,
    threshold_levels_electrons,
)

#: Families of sensors: what their output is and how it is turned into light (measure.comparison).
FAMILIES = ("spike", "frame", "segmented", "overflow", "highspeed", "gated")

_UNSET = object()


def _replace(obj, changes: dict):
    return dataclasses.replace(obj, **changes) if changes else obj


def _with_pixel(pixel, by: dict):
    """``pixel`` with its optics and pixel fields replaced by the settings grouped in ``by``."""
    optics = _replace(pixel.optics, by.get("optics", {}))
    changes = dict(by.get("pixel", {}))
    if optics is not pixel.optics:
        changes["optics"] = optics
    return _replace(pixel, changes)


# ---------------------------------------------------------------------- entries
@dataclass(frozen=True)
class SensorEntry:
    """One sensor of the catalogue.

    Attributes
    ----------
    name, label, description : str
        The name every command takes, a short label for tables and figures, one line for users.
    family : str
        One of :data:`FAMILIES`: the kind of output and how it becomes light.
    resolution : (int, int) or None
        The sensor's own pixel array (rows, columns); None: the scene's.
    scene_shape : (int, int)
        Rows and columns of a built-in scene shot with this sensor when none are given.
    compare_settings : dict
        Settings ``compare`` and ``sweep`` shoot it with (simulation detail, not the camera's
        physics, e.g. more points of the light per exposure).
    """

    name: str
    label: str
    description: str
    family: str
    make: Callable = field(repr=False, compare=False)
    space: Callable = field(repr=False, compare=False)
    resolution: tuple | None = None
    scene_shape: tuple = (64, 128)
    compare_settings: dict = field(default_factory=dict)

    @cached_property
    def parameters(self) -> dict[str, Parameter]:
        """Every parameter this sensor takes, by name."""
        return self.space()

    def parameter(self, name: str) -> Parameter:
        params = self.parameters
        if name not in params:
            raise ViformError(f"{name!r} is not a parameter of sensor {self.name!r}; its parameters: "
                              f"{', '.join(sorted(params))} (viform sensors show {self.name})")
        return params[name]

    def check_settings(self, settings: dict) -> dict:
        """``settings`` with every name known and every value within its parameter's range."""
        return {name: self.parameter(name).check(value) for name, value in settings.items()}

    def build(self, *, height=_UNSET, width=_UNSET, **settings) -> Sensor:
        """The sensor with ``settings`` (parameter name → value) applied.

        ``height``/``width`` set its pixel array (default: :attr:`resolution`; None: the scene's).
        Errors name the parameter, its unit and what is allowed.
        """
        checked = self.check_settings(settings)
        by: dict[str, dict] = {}
        for name, value in checked.items():
            p = self.parameters[name]
            by.setdefault(p.where, {})[p.field] = value
        own = self.resolution or (None, None)
        h = own[0] if height is _UNSET else height
        w = own[1] if width is _UNSET else width
        try:
            return self.make(by, h, w)
        except (ViformError, ValueError, TypeError) as exc:
            if not checked:
                raise
            text = ", ".join(self.parameters[n].setting_text(v) for n, v in checked.items())
            raise ViformError(f"sensor {self.name!r} with {text}: {exc}") from None

    def defaults(self) -> dict:
        return {n: p.default for n, p in self.parameters.items()}


# frame cameras ------------------------------------------------------------------
def frame_entry(name, label, description, pixel: Callable[..., FramePixelParameters], design=None,
                **camera) -> SensorEntry:
    """The entry of a :class:`FrameSensor` preset: its pixel is ``pixel(**design)`` (``design``: the
    arguments of the pixel's own builder, e.g. a LOFIC capacitor), ``camera`` the constructor's
    arguments this preset fixes (``exposure_s``, ``frame_rate_hz``, …). Every field of the pixel and
    its optics and every constructor argument becomes a parameter."""
    design = design or {}

    def base_pixel(by):
        return pixel(**{**design, **by.get("design", {})})

    def make(by, h, w):
        return FrameSensor(_with_pixel(base_pixel(by), by), height=h, width=w, **{**camera, **by.get("camera", {})})

    def space():
        p = base_pixel({})
        return merged({n: parameter_for(n, v, "design") for n, v in design.items()}, arguments_of(FrameSensor, camera),
                      fields_of(p, "pixel"), fields_of(p.optics, "optics"))

    return SensorEntry(name, label, description, "frame", make, space)


def _segmented_entry(name, label, description, fractions, barriers_fw):
    exposure = presets.PAPER001_EXPOSURE_S

    def make(by, h, w):
        pixel = _with_pixel(presets.paper001_pixel_parameters(), by)
        short = by.get("shorthand", {})
        times = [f * exposure for f in fractions]
        if "exposure_s" in short or "first_segment_fraction" in short:
            t = np.asarray(times, dtype=np.float64)
            total = float(short.get("exposure_s", t.sum()))
            check_positive("exposure_s", total)
            if "first_segment_fraction" in short:
                f = float(short["first_segment_fraction"])
                t = np.array([f, 1 - f])
            times = (t / t.sum() * total).tolist()
        if "barrier_fraction" in short:
            levels = [float(short["barrier_fraction"]) * pixel.full_well_electrons]
        else:
            levels = [b * pixel.full_well_electrons for b in barriers_fw]
        return SegmentedExposureSensor(pixel, tuple(times), tuple(levels), height=h, width=w,
                                       **{"frame_rate_hz": 60.0, **by.get("camera", {})})

    def space():
        p = presets.paper001_pixel_parameters()
        out = {"exposure_s": parameter_for("exposure_s", exposure, "shorthand",
                                        doc="total exposure, s (every segment scaled, ratios kept)")}
        if len(fractions) == 2:
            out["first_segment_fraction"] = parameter_for("first_segment_fraction", fractions[0], "shorthand",
                                                       doc="T1 / (T1 + T2)")
            out["barrier_fraction"] = parameter_for("barrier_fraction", barriers_fw[0], "shorthand",
                                                 doc="barrier B1 / full well")
        return merged(out, arguments_of(SegmentedExposureSensor, {"frame_rate_hz": 60.0}), fields_of(p, "pixel"),
                      fields_of(p.optics, "optics"))

    return SensorEntry(name, label, description, "segmented", make, space)


_INTEGRATIONS = ("long_integration_s", "medium_integration_s", "short_integration_s")


def _overflow_entry(name, label, description, **camera):
    def make(by, h, w):
        pixel = _with_pixel(paper003_pixel_parameters(), by)
        short = by.get("shorthand", {})
        kw = {**camera, **by.get("camera", {})}
        if short:
            times = list(PAPER003_INTEGRATIONS_S)
            for i, n in enumerate(_INTEGRATIONS):
                if n in short:
                    times[i] = float(short[n])
            kw["integration_times_s"] = tuple(times)
        return OverflowSensor(pixel, height=h, width=w, **kw)

    def space():
        p = paper003_pixel_parameters()
        out = {n: parameter_for(n, t, "shorthand", doc="one of the three integrations, s")
               for n, t in zip(_INTEGRATIONS, PAPER003_INTEGRATIONS_S, strict=True)}
        return merged(out, arguments_of(OverflowSensor, camera), fields_of(p, "pixel"), fields_of(p.optics, "optics"))

    return SensorEntry(name, label, description, "overflow", make, space)


# spike cameras ------------------------------------------------------------------
def _spike_make(base: SpikeSensorParameters, by: dict, h, w) -> SpikeSensor:
    changes = dict(by.get("pixel", {}))
    level = by.get("shorthand", {}).get("threshold_level")
    if level is not None:
        if "threshold_electrons" in changes:
            raise ViformError("give either threshold_level or threshold_electrons, not both")
        changes["threshold_electrons"] = threshold_level_electrons(level)
    return SpikeSensor(_with_pixel(base, {"pixel": changes, "optics": by.get("optics", {})}), h, w)


def spike_sensor(parameters: SpikeSensorParameters, height=None, width=None, **settings) -> SpikeSensor:
    """A spike camera of any parameters (e.g. a calibrated preset file's) with ``settings`` applied as
    the catalogue applies them to its spike cameras (the same names, units and ranges)."""
    space = SENSORS["spike"].parameters
    by: dict[str, dict] = {}
    for name, value in settings.items():
        if name not in space:
            raise ViformError(f"{name!r} is not a parameter of a spike camera; its parameters: {', '.join(space)}")
        by.setdefault(space[name].where, {})[space[name].field] = space[name].check(value)
    return _spike_make(parameters, by, height, width)


def _spike_entry(name, label, description, parameters: Callable[[], SpikeSensorParameters], resolution=None,
                 scene_shape=(250, 400)):
    def make(by, h, w):
        return _spike_make(parameters(), by, h, w)

    def space():
        p = parameters()
        levels = threshold_levels_electrons()
        level = next((k for k, q in enumerate(levels) if q == p.threshold_electrons), None)
        out = {"threshold_level": parameter_for(
            "threshold_level", level, "shorthand", kind="int", optional=True,
            doc=f"the chip's threshold level 0…{N_THRESHOLD_LEVELS - 1} (Q = (level + 1)·1 250 e⁻)")}
        return merged(out, fields_of(p, "pixel"), fields_of(p.optics, "optics"))

    return SensorEntry(name, label, description, "spike", make, space, resolution,
                       resolution if resolution is not None else scene_shape)


def _chip_entry(name: str, label: str) -> SensorEntry:
    preset = load_spike_preset(name)
    return _spike_entry(name, label, preset.description, lambda: load_spike_preset(name).parameters,
                        (preset.height, preset.width))


def _seed000_spike() -> SpikeSensorParameters:
    """Seed 000's worked example: Q = 100 e⁻ (§4.3), 40 kHz, a 10 µm pixel at QE 0.7."""
    return SpikeSensorParameters(optics=PixelOptics(pixel_pitch_m=10e-6, quantum_efficiency=0.7))


# the high-speed camera -------------------------------------------------------------
def _highspeed_entry() -> SensorEntry:
    def make(by, h, w):
        return HighSpeedCamera(_with_pixel(lux13hs_pixel_parameters(), by), **by.get("camera", {}))

    def space():
        p = lux13hs_pixel_parameters()
        out = arguments_of(HighSpeedCamera, {})
        out["mode"] = dataclasses.replace(out["mode"], kind="choice", choices=("reduced", "normal"))
        pixel = fields_of(p, "pixel")
        pixel["adc_bits"] = dataclasses.replace(pixel["adc_bits"], low=8)  # its output is the high 8 bits
        return merged(out, pixel, fields_of(p.optics, "optics"))

    return SensorEntry("highspeed", "high-speed 1 667 fps, AE (highspeed)",
                       "high-speed camera (LUX13HS-like, 1 667 fps at 1280×720) with auto-exposure, 8-bit frames",
                       "highspeed", make, space, compare_settings={"scene_samples": 8})


# the gated camera ---------------------------------------------------------------------
#: Pixel fields the gated CCD does not use (its frame is read at once from the vertical register).
_GATED_UNUSED_PIXEL = ("readout_time_s", "parasitic_light_sensitivity", "storage_leakage_e_per_s",
                       "black_sun_fraction", "reset_sample_time_s")
#: The catalogue's gated camera: 200 pulses accumulated in the vertical register (fits a 25 fps
#: frame), gate from 40 m, so fog closer than 40 m, which would veil everything, is not recorded.
GATED_CAMERA = {"pulses": 200, "gate_range_m": 40.0, "mode": "accumulate", "frame_rate_hz": 25.0}


def _gated_entry() -> SensorEntry:
    def make(by, h, w):
        ccd_kw = dict(by.get("ccd", {}))
        default = InterlineCCDParameters()
        pixel = _with_pixel(default.pixel, by)
        if pixel is not default.pixel:
            ccd_kw["pixel"] = pixel
        if "part" in ccd_kw:
            ccd = interline_ccd_parameters(ccd_kw.pop("part"), **ccd_kw)
        else:
            ccd = InterlineCCDParameters(**ccd_kw) if ccd_kw else None
        laser = PulsedLaser(**by["laser"]) if by.get("laser") else None
        receiver = Receiver(**by["receiver"]) if by.get("receiver") else None
        return GatedInterlineCCD(**{**GATED_CAMERA, **by.get("camera", {})}, parameters=ccd, laser=laser,
                                 receiver=receiver)

    def space():
        ccd = InterlineCCDParameters()
        out = arguments_of(GatedInterlineCCD, GATED_CAMERA, skip=("laser", "receiver"))
        out["mode"] = dataclasses.replace(out["mode"], kind="choice", choices=MODES)
        return merged(out, fields_of(ccd, "ccd"), fields_of(ccd.pixel, "pixel", skip=_GATED_UNUSED_PIXEL),
                      fields_of(ccd.pixel.optics, "optics", skip=("wavelength_m",)),
                      fields_of(PulsedLaser(), "laser", prefix="laser_"),
                      fields_of(Receiver(), "receiver", prefix="receiver_"))

    return SensorEntry("gated", "gated CCD, laser returns (gated)",
                       "range-gated interline CCD, 905 nm laser, 200 pulses a frame, gate from 40 m "
                       "(scenes with range: night-road-fog)", "gated", make, space)


def _entries() -> dict[str, SensorEntry]:
    paper001 = presets.paper001_pixel_parameters
    paper003_t = sum(PAPER003_INTEGRATIONS_S)
    entries = [
        _spike_entry("spike", "spike camera, Q = 100 e⁻ (spike)",
                     "spike camera of seed 000's worked example: Q = 100 e⁻, 40 kHz, 10 µm pixels at QE 0.7, "
                     "the scene's size", _seed000_spike),
        _chip_entry("spikeone", "SpikeOne chip (spikeone)"),
        _chip_entry("spiketwo", "SpikeTwo chip, 20 kHz (spiketwo)"),
        _chip_entry("spiketwo-40k", "SpikeTwo chip, 40 kHz (spiketwo-40k)"),
        frame_entry("cmos-short", "CMOS 1 ms (cmos-short)", "conventional global-shutter CMOS, 1 ms exposure at "
                     "30 fps", FramePixelParameters, exposure_s=1e-3, frame_rate_hz=30.0),
        frame_entry("cmos", "CMOS 10 ms (cmos)", "conventional global-shutter CMOS, 10 ms exposure at 30 fps",
                     FramePixelParameters, exposure_s=10e-3, frame_rate_hz=30.0),
        frame_entry("seed001-normal", "5T normal mode 130 µs (seed001-normal)",
                     "seed 001's 5T global-shutter pixel, normal mode, 130 µs exposure at 60 fps", paper001,
                     exposure_s=presets.PAPER001_EXPOSURE_S, frame_rate_hz=60.0),
        _segmented_entry("seed001-2seg", "segmented, 2 segments (seed001-2seg)",
                         "segmented exposure, two segments (T1:T2 = 5:1, barrier 5/12 of the full well), 130 µs "
                         "at 60 fps", presets.PAPER001_2SEG_FRACTIONS, presets.PAPER001_2SEG_BARRIERS_FW),
        _segmented_entry("seed001-3seg", "segmented, 3 segments (seed001-3seg)",
                         "segmented exposure, three segments (0.74:0.25:0.01, barriers 0.344/0.874 of the full "
                         "well), 130 µs at 60 fps", presets.PAPER001_3SEG_FRACTIONS, presets.PAPER001_3SEG_BARRIERS_FW),
        frame_entry("seed003-4t", "plain 4T 33 ms (seed003-4t)", "plain 4T APS, 33.33 ms integration at 30 fps",
                     paper003_pixel_parameters, exposure_s=paper003_t, frame_rate_hz=30.0),
        _overflow_entry("seed003-overflow", "conditional overflow (seed003-overflow)",
                        "conditional-overflow pixel, C_F = 500 fF, three integrations (32.8/0.5/0.03 ms) at 30 fps"),
        _overflow_entry("seed003-overflow-ktc", "conditional overflow with kTC noise (seed003-overflow-ktc)",
                        "conditional-overflow pixel with the readout's reset (kTC) noise (120 e⁻ per reset)",
                        ktc_noise=True),
        frame_entry("seed003-lofic", "lateral overflow 33 ms (seed003-lofic)",
                     "lateral-overflow capacitor pixel, C_S = 500 fF read with the photodiode at low gain, "
                     "33.33 ms at 30 fps", lofic_pixel_parameters,
                     design={"lateral_capacitance_f": 500e-15, "temperature_k": 300.0},
                     exposure_s=paper003_t, frame_rate_hz=30.0),
        _highspeed_entry(),
        _gated_entry(),
    ]
    return {e.name: e for e in entries}


#: Every sensor, by name, in report order.
SENSORS: dict[str, SensorEntry] = _entries()
assert set(SPIKE_PRESET_NAMES) <= set(SENSORS)
assert all(e.family in FAMILIES for e in SENSORS.values())


def register(new: SensorEntry) -> SensorEntry:
    """Add ``new`` to :data:`SENSORS` (a name already there is refused): every command then takes it.

    A sensor of the package is an entry of :func:`_entries`; this is for a sensor defined outside it
    (a notebook, a study's own preset).

    Parameters
    ----------
    new : SensorEntry
        The entry (:func:`frame_entry` builds one for a preset of a frame camera).

    Returns
    -------
    SensorEntry
        ``new``, now in the catalogue.
    """
    if new.name in SENSORS:
        raise ViformError(f"sensor {new.name!r} is already in the catalogue: choose another name")
    if new.family not in FAMILIES:
        raise ViformError(f"family = {new.family!r} is not allowed: choose one of {', '.join(FAMILIES)}")
    new.parameters  # noqa: B018 - its parameters are read (and checked for clashes) now, not at first use
    SENSORS[new.name] = new
    return new


def sensor_names(*families: str) -> list[str]:
    """Names of the sensors of ``families`` (all when none is given), in catalogue order.

    Parameters
    ----------
    *families : str
        Families to list (of :data:`FAMILIES`: ``"frame"``, ``"spike"`` ...).

    Returns
    -------
    list of str
        The sensors' names.

    Examples
    --------
    >>> sensor_names("spike")
    ['spike', 'spikeone', 'spiketwo', 'spiketwo-40k']
    """
    return [n for n, e in SENSORS.items() if not families or e.family in families]


def entry(name: str, *, choices=None, renamed: dict | None = None, what: str = "sensor") -> SensorEntry:
    """The catalogue entry ``name``; ``choices`` limits the names allowed (a command's own list),
    ``renamed`` maps names that changed meaning to the line that points to the new name."""
    if renamed and name in renamed:
        raise ViformError(f"{what} = {name!r} is not allowed: {renamed[name]}")
    allowed = list(choices) if choices is not None else list(SENSORS)
    if name not in SENSORS or name not in allowed:
        raise ViformError(f"{what} = {name!r} is not allowed: choose one of {', '.join(allowed)}")
    return SENSORS[name]


def make_sensor(name: str, **settings) -> Sensor:
    """Build the catalogue's sensor ``name`` with ``settings`` (parameter name → value).

    ``height``/``width`` set the pixel array (None: the scene's). Any parameter of
    ``SENSORS[name].parameters`` may be given: a pixel field (``read_noise_electrons``,
    ``parasitic_light_sensitivity``), an optics field (``quantum_efficiency``), a camera argument
    (``exposure_s``, ``comparator_noise_v``) or a shorthand (``threshold_level``).

    Parameters
    ----------
    name : str
        A name of :data:`SENSORS` (:func:`sensor_names`).
    **settings
        Parameter name → value, any of ``SENSORS[name].parameters`` (each with its unit in its
        name: ``exposure_s``, ``read_noise_electrons`` ...), plus ``height`` and ``width`` (pixels).

    Returns
    -------
    Sensor
        The sensor, ready to ``capture(scene, duration_s, seed=...)``.

    Raises
    ------
    ViformError
        For an unknown name or parameter, or a value out of its range (the message names it).

    Examples
    --------
    >>> sensor = make_sensor("cmos", height=8, width=8, exposure_s=1e-3)
    >>> type(sensor).__name__, sensor.exposure_s, sensor.frame_rate_hz
    ('FrameSensor', 0.001, 30.0)
    """
    return entry(name).build(**settings)


def describe(name: str) -> str:
    """One line about sensor ``name``."""
    return entry(name).description
