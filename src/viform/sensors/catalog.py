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
import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from viform._validate import ViformError, check_positive
from viform.light.laser import PulsedLaser, Receiver
from viform.light.radiometry import PixelOptics
from viform.sensors import presets
from viform.sensors.auto_exposure import METERS
from viform.sensors.base import Sensor
from viform.sensors.frame import FramePixelParameters, FrameSensor
from viform.sensors.gated_ccd import MODES, GatedInterlineCCD, InterlineCCDParameters, interline_ccd_parameters
from viform.sensors.gated_waveforms import DRIVES
from viform.sensors.highspeed import HighSpeedCamera, lux13hs_pixel_parameters
from viform.sensors.overflow import (
    SEED003_INTEGRATIONS_S,
    OverflowSensor,
    lofic_pixel_parameters,
    seed003_pixel_parameters,
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


# ---------------------------------------------------------------------- parameters
#: Units by the end of a parameter's name (the longest match wins), then by whole name.
_SUFFIX_UNITS = (
    ("_e_per_s", "e⁻/s"), ("_v_per_e", "V/e⁻"), ("_electrons", "e⁻"), ("_hz", "Hz"), ("_s", "s"), ("_m", "m"),
    ("_f", "F"), ("_v", "V"), ("_dn", "DN"), ("_w", "W"), ("_rad", "rad"), ("_k", "K"), ("_px", "px"),
    ("_fraction", "fraction"), ("_gray", "gray level (0–255)"), ("_frames", "frames"), ("_ratio", "ratio"),
)
_NAME_UNITS = {
    "quantum_efficiency": "e⁻/photon", "fill_factor": "fraction", "parasitic_light_sensitivity": "fraction",
    "analog_gain": "×", "adc_bits": "bits", "pulses": "pulses", "threshold_level": "level (0–15)",
    "scene_samples": "points", "fixed_pattern_seed": "seed", "overflow_capacitance_spread": "fraction",
    "transmitter_efficiency": "fraction", "laser_transmitter_efficiency": "fraction",
    "receiver_transmission": "fraction", "receiver_f_number": "f-number", "junction_grading_m": "exponent",
    "sensor_height_px": "px", "sensor_width_px": "px", "ae_saturated_cut": "factor",
}
_BARE = object()
#: Allowed ranges that differ from "a finite number > 0" (float) or "≥ 0" (int): (low, high, low_open, high_open);
#: None for no bound; by name, or by (part, name) where two parts use one name differently. The model's own validation stays in force (cross-parameter limits, e.g. an
#: exposure within the frame period); a test checks that each bound here is one the model enforces.
_RANGES = {
    "quantum_efficiency": (0.0, 1.0, True, False), "fill_factor": (0.0, 1.0, True, False),
    "parasitic_light_sensitivity": (0.0, 1.0, False, False), "black_sun_fraction": (0.0, 1.0, False, False),
    "shutter_leak_ratio": (0.0, 1.0, False, False), "adc_bits": (1, 16, False, False),
    "read_noise_electrons": (0.0, None, False, False), "dark_current_e_per_s": (0.0, None, False, False),
    "dsnu_electrons": (0.0, None, False, False), "prnu_fraction": (0.0, None, False, False),
    "black_offset_dn": (0.0, None, False, False), "readout_time_s": (0.0, None, False, False),
    "storage_leakage_e_per_s": (0.0, None, False, False), "reset_sample_time_s": (0.0, None, False, False),
    "barrier_spread_fraction": (0.0, None, False, False), "barrier_softness_electrons": (0.0, None, False, False),
    "clamp_noise_electrons": (0.0, None, False, False), "first_segment_fraction": (0.0, 1.0, True, True),
    "barrier_fraction": (0.0, 1.0, True, True),
    "comparator_offset_v": (0.0, None, False, False), "comparator_noise_v": (0.0, None, False, False),
    "overflow_capacitance_spread": (0.0, 0.3, False, False),
    "charge_injection_electrons": (-1e7, 1e7, False, False), "column_bus_capacitance_f": (0.0, None, False, False),
    "junction_grading_m": (0.0, 0.9, False, False),
    "threshold_spread_fraction": (0.0, 0.5, False, True), "gain_spread_fraction": (0.0, 1.0, False, True),
    "dark_current_spread_fraction": (0.0, 10.0, False, False), "hot_pixel_fraction": (0.0, 1.0, False, False),
    "threshold_electrons": (0.5, float(2**26), True, False),  # whole electrons: round(Q) in [1, 2^26]
    ("ccd", "readout_time_s"): (0.0, None, True, False),
    "hot_pixel_dark_current_e_per_s": (0.0, None, False, False), "dead_time_s": (0.0, None, False, False),
    "threshold_level": (0, N_THRESHOLD_LEVELS - 1, False, False),
    "target_gray": (0.0, 255.0, False, False), "band_gray": (0.0, None, False, False),
    "ae_latency_frames": (0, 8, False, False), "ae_saturated_cut": (0.0, 1.0, True, True),
    "scene_samples": (1, None, False, False), "pulses": (1, None, False, False),
    "gate_range_m": (0.0, None, False, False), "gate_jitter_s": (0.0, None, False, False),
    "sub_fall_time_s": (0.0, None, False, False), "laser_rise_time_s": (0.0, None, False, False),
    "sensor_height_px": (1, None, False, False), "sensor_width_px": (1, None, False, False),
    "laser_transmitter_efficiency": (0.0, 1.0, True, False),
    "laser_divergence_x_rad": (0.0, math.pi, True, False), "laser_divergence_y_rad": (0.0, math.pi, True, False),
    "receiver_f_number": (0.5, 64.0, False, False), "receiver_transmission": (0.0, 1.0, True, False),
    "fixed_pattern_seed": (0, None, False, False),
}
#: Choices of the text-valued parameters.
_CHOICES = {
    "reset": ("self", "readout"), "meter": tuple(METERS), "part": tuple(DRIVES),
}


@dataclass(frozen=True)
class Parameter:
    """One parameter of a sensor, as a user sets it (``--set NAME=VALUE``, ``make_sensor(name, NAME=value)``).

    Attributes
    ----------
    name : str
        The name users give (units in the name).
    kind : {"float", "int", "bool", "choice", "text"}
    default : object
        The entry's value when not set (None: off / derived, see ``doc``).
    unit : str
    where : str
        Which part of the model holds it: "pixel", "optics", "camera", "ccd", "laser", "receiver",
        "design" (the pixel's design, e.g. the LOFIC capacitor) or "shorthand" (sets several fields).
    field : str
        The model's own name for it (differs for the laser's and receiver's ``laser_*``/``receiver_*``).
    low, high : float or None
        Allowed range (None: unbounded), open at ``low_open``/``high_open``.
    optional : bool
        None (``none`` on the command line) is allowed: the model then derives the value.
    choices : tuple
        Allowed values of a "choice".
    doc : str
    """

    name: str
    kind: str
    default: object
    unit: str = ""
    where: str = "camera"
    field: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    optional: bool = False
    choices: tuple = ()
    doc: str = ""

    def allowed(self) -> str:
        """The allowed values in words: "> 0", "in (0, 1]", "true or false", "one of a, b" …"""
        if self.kind == "bool":
            text = "true or false"
        elif self.kind == "choice":
            text = "one of " + ", ".join(self.choices)
        elif self.kind == "text":
            text = "text"
        else:
            whole = "a whole number" if self.kind == "int" else "a number"
            lo, hi = self.low, self.high
            if lo is not None and hi is not None:
                text = f"{whole} in {'(' if self.low_open else '['}{lo:g}, {hi:g}{')' if self.high_open else ']'}"
            elif lo is not None:
                text = f"{whole} {'>' if self.low_open else '≥'} {lo:g}"
            elif hi is not None:
                text = f"{whole} {'<' if self.high_open else '≤'} {hi:g}"
            else:
                text = f"any finite {'whole ' if self.kind == 'int' else ''}number"
        return text + (", or none" if self.optional else "")

    def with_unit(self) -> str:
        return f"{self.name} ({self.unit})" if self.unit else self.name

    def setting_text(self, value) -> str:
        """``name = value unit (allowed: …)``, as errors about a setting show it."""
        unit = f" {self.unit}" if self.unit and self.kind in ("float", "int") and value is not None else ""
        return f"{self.name} = {value!r}{unit} (allowed: {self.allowed()})"

    def _refuse(self, value, why: str = "", verdict: str = "is not allowed") -> ViformError:
        numeric = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
        unit = f" {self.unit}" if self.unit and self.kind in ("float", "int") and numeric else ""
        return ViformError(f"{self.name} = {value!r}{unit} {verdict}: it must be {self.allowed()}"
                           + (f" ({why})" if why else ""))

    def check(self, value):
        """``value`` as this parameter's type, within its range; the error names the parameter, its unit
        and the allowed values."""
        if value is None:
            if self.optional:
                return None
            raise self._refuse(value)
        if self.kind == "bool":
            if isinstance(value, (bool, np.bool_)):
                return bool(value)
            raise self._refuse(value)
        if self.kind in ("choice", "text"):
            if not isinstance(value, str) or (self.kind == "choice" and value not in self.choices):
                raise self._refuse(value)
            return value
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise self._refuse(value)
        if not math.isfinite(float(value)):
            raise self._refuse(value, "a finite number")
        if self.kind == "int":
            if float(value) != round(float(value)):
                raise self._refuse(value)
            value = int(round(float(value)))
        else:
            value = float(value)
        lo, hi = self.low, self.high
        if lo is not None and (value <= lo if self.low_open else value < lo):
            raise self._refuse(value)
        if hi is not None and (value >= hi if self.high_open else value > hi):
            raise self._refuse(value)
        return value

    def parse(self, text: str):
        """A value from text (``true``/``false``, a number, ``none``, a choice), checked."""
        t = str(text).strip()
        low = t.lower()
        if self.optional and low in ("none", "null", "auto"):
            return None
        if self.kind == "bool":
            if low in ("true", "on", "yes", "1"):
                return True
            if low in ("false", "off", "no", "0"):
                return False
            raise self._refuse(t)
        if self.kind in ("choice", "text"):
            return self.check(t)
        try:
            value = float(t)
        except ValueError:
            raise self._refuse(t, verdict="is not a number") from None
        return self.check(value)

    def default_text(self) -> str:
        v = self.default
        if v is None:
            return "none"
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return f"{v:.6g}"
        return str(v)


def _unit(name: str) -> str:
    if name in _NAME_UNITS:
        return _NAME_UNITS[name]
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def _parameter(name: str, default, where: str, field_name: str | None = None, doc: str = "",
               kind: str | None = None, optional: bool | None = None) -> Parameter:
    """A :class:`Parameter` whose kind, unit and range follow from its name and default."""
    if kind is None:
        if isinstance(default, bool):
            kind = "bool"
        elif isinstance(default, (int, np.integer)):
            kind = "int"
        elif isinstance(default, str):
            kind = "choice" if (field_name or name) in _CHOICES else "text"
        else:
            kind = "float"
    rng = _RANGES.get((where, name), _RANGES.get(name))
    if rng is None:
        rng = (0.0, None, True, False) if kind == "float" else (0, None, False, False) if kind == "int" else \
            (None, None, False, False)
    return Parameter(name, kind, default, _unit(name), where, field_name or name, rng[0], rng[1], rng[2], rng[3],
                     default is None if optional is None else optional, _CHOICES.get(field_name or name, ()), doc)


def _fields(obj, where: str, prefix: str = "", skip=(), docs: dict | None = None) -> dict[str, Parameter]:
    """Every field of the dataclass ``obj`` (scalars, text) as parameters, named ``prefix + field``."""
    out = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.name in skip or dataclasses.is_dataclass(value) or isinstance(value, (tuple, list, dict)):
            continue
        name = prefix + f.name
        optional = value is None or f.default is None
        out[name] = _parameter(name, value, where, f.name, (docs or {}).get(f.name, ""), optional=optional,
                               kind="float" if value is None else None)
    return out


def _arguments(cls, defaults: dict, skip=()) -> dict[str, Parameter]:
    """The keyword arguments of ``cls``'s constructor (scalars, text) as "camera" parameters."""
    out = {}
    for name, p in inspect.signature(cls.__init__).parameters.items():
        if name in ("self", "parameters", "height", "width") or name in skip or p.kind is p.VAR_KEYWORD:
            continue
        value = defaults.get(name, p.default)
        if value is inspect.Parameter.empty or isinstance(value, (tuple, list)) or dataclasses.is_dataclass(value):
            continue
        out[name] = _parameter(name, value, "camera", optional=value is None or p.default is None,
                               kind="float" if value is None else None)
    return out


def _merge(*groups: dict) -> dict[str, Parameter]:
    """One namespace of parameters: a name given by two parts of a model is an error of the catalogue."""
    out: dict[str, Parameter] = {}
    for group in groups:
        for name, p in group.items():
            if name in out:
                raise AssertionError(f"parameter {name!r} is both {out[name].where} and {p.where}: prefix one")
            out[name] = p
    return out


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
def _frame_entry(name, label, description, pixel: Callable[..., FramePixelParameters], design=None, **camera):
    """A :class:`FrameSensor` preset: ``pixel(**design)`` and the camera's arguments."""
    design = design or {}

    def base_pixel(by):
        return pixel(**{**design, **by.get("design", {})})

    def make(by, h, w):
        return FrameSensor(_with_pixel(base_pixel(by), by), height=h, width=w, **{**camera, **by.get("camera", {})})

    def space():
        p = base_pixel({})
        return _merge({n: _parameter(n, v, "design") for n, v in design.items()}, _arguments(FrameSensor, camera),
                      _fields(p, "pixel"), _fields(p.optics, "optics"))

    return SensorEntry(name, label, description, "frame", make, space)


def _segmented_entry(name, label, description, fractions, barriers_fw):
    exposure = presets.SEED001_EXPOSURE_S

    def make(by, h, w):
        pixel = _with_pixel(presets.seed001_pixel_parameters(), by)
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
        p = presets.seed001_pixel_parameters()
        out = {"exposure_s": _parameter("exposure_s", exposure, "shorthand",
                                        doc="total exposure, s (every segment scaled, ratios kept)")}
        if len(fractions) == 2:
            out["first_segment_fraction"] = _parameter("first_segment_fraction", fractions[0], "shorthand",
                                                       doc="T1 / (T1 + T2)")
            out["barrier_fraction"] = _parameter("barrier_fraction", barriers_fw[0], "shorthand",
                                                 doc="barrier B1 / full well")
        return _merge(out, _arguments(SegmentedExposureSensor, {"frame_rate_hz": 60.0}), _fields(p, "pixel"),
                      _fields(p.optics, "optics"))

    return SensorEntry(name, label, description, "segmented", make, space)


_INTEGRATIONS = ("long_integration_s", "medium_integration_s", "short_integration_s")


def _overflow_entry(name, label, description, **camera):
    def make(by, h, w):
        pixel = _with_pixel(seed003_pixel_parameters(), by)
        short = by.get("shorthand", {})
        kw = {**camera, **by.get("camera", {})}
        if short:
            times = list(SEED003_INTEGRATIONS_S)
            for i, n in enumerate(_INTEGRATIONS):
                if n in short:
                    times[i] = float(short[n])
            kw["integration_times_s"] = tuple(times)
        return OverflowSensor(pixel, height=h, width=w, **kw)

    def space():
        p = seed003_pixel_parameters()
        out = {n: _parameter(n, t, "shorthand", doc="one of the three integrations, s")
               for n, t in zip(_INTEGRATIONS, SEED003_INTEGRATIONS_S, strict=True)}
        return _merge(out, _arguments(OverflowSensor, camera), _fields(p, "pixel"), _fields(p.optics, "optics"))

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
        out = {"threshold_level": _parameter(
            "threshold_level", level, "shorthand", kind="int", optional=True,
            doc=f"the chip's threshold level 0…{N_THRESHOLD_LEVELS - 1} (Q = (level + 1)·1 250 e⁻)")}
        return _merge(out, _fields(p, "pixel"), _fields(p.optics, "optics"))

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
        out = _arguments(HighSpeedCamera, {})
        out["mode"] = dataclasses.replace(out["mode"], kind="choice", choices=("reduced", "normal"))
        pixel = _fields(p, "pixel")
        pixel["adc_bits"] = dataclasses.replace(pixel["adc_bits"], low=8)  # its output is the high 8 bits
        return _merge(out, pixel, _fields(p.optics, "optics"))

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
        out = _arguments(GatedInterlineCCD, GATED_CAMERA, skip=("laser", "receiver"))
        out["mode"] = dataclasses.replace(out["mode"], kind="choice", choices=MODES)
        return _merge(out, _fields(ccd, "ccd"), _fields(ccd.pixel, "pixel", skip=_GATED_UNUSED_PIXEL),
                      _fields(ccd.pixel.optics, "optics", skip=("wavelength_m",)),
                      _fields(PulsedLaser(), "laser", prefix="laser_"),
                      _fields(Receiver(), "receiver", prefix="receiver_"))

    return SensorEntry("gated", "gated CCD, laser returns (gated)",
                       "range-gated interline CCD, 905 nm laser, 200 pulses a frame, gate from 40 m "
                       "(scenes with range: night-road-fog)", "gated", make, space)


def _entries() -> dict[str, SensorEntry]:
    seed001 = presets.seed001_pixel_parameters
    seed003_t = sum(SEED003_INTEGRATIONS_S)
    entries = [
        _spike_entry("spike", "spike camera, Q = 100 e⁻ (spike)",
                     "spike camera of seed 000's worked example: Q = 100 e⁻, 40 kHz, 10 µm pixels at QE 0.7, "
                     "the scene's size", _seed000_spike),
        _chip_entry("spikeone", "SpikeOne chip (spikeone)"),
        _chip_entry("spiketwo", "SpikeTwo chip, 20 kHz (spiketwo)"),
        _chip_entry("spiketwo-40k", "SpikeTwo chip, 40 kHz (spiketwo-40k)"),
        _frame_entry("cmos-short", "CMOS 1 ms (cmos-short)", "conventional global-shutter CMOS, 1 ms exposure at "
                     "30 fps", FramePixelParameters, exposure_s=1e-3, frame_rate_hz=30.0),
        _frame_entry("cmos", "CMOS 10 ms (cmos)", "conventional global-shutter CMOS, 10 ms exposure at 30 fps",
                     FramePixelParameters, exposure_s=10e-3, frame_rate_hz=30.0),
        _frame_entry("seed001-normal", "5T normal mode 130 µs (seed001-normal)",
                     "seed 001's 5T global-shutter pixel, normal mode, 130 µs exposure at 60 fps", seed001,
                     exposure_s=presets.SEED001_EXPOSURE_S, frame_rate_hz=60.0),
        _segmented_entry("seed001-2seg", "segmented, 2 segments (seed001-2seg)",
                         "segmented exposure, two segments (T1:T2 = 5:1, barrier 5/12 of the full well), 130 µs "
                         "at 60 fps", presets.SEED001_2SEG_FRACTIONS, presets.SEED001_2SEG_BARRIERS_FW),
        _segmented_entry("seed001-3seg", "segmented, 3 segments (seed001-3seg)",
                         "segmented exposure, three segments (0.74:0.25:0.01, barriers 0.344/0.874 of the full "
                         "well), 130 µs at 60 fps", presets.SEED001_3SEG_FRACTIONS, presets.SEED001_3SEG_BARRIERS_FW),
        _frame_entry("seed003-4t", "plain 4T 33 ms (seed003-4t)", "plain 4T APS, 33.33 ms integration at 30 fps",
                     seed003_pixel_parameters, exposure_s=seed003_t, frame_rate_hz=30.0),
        _overflow_entry("seed003-overflow", "conditional overflow (seed003-overflow)",
                        "conditional-overflow pixel, C_F = 500 fF, three integrations (32.8/0.5/0.03 ms) at 30 fps"),
        _overflow_entry("seed003-overflow-ktc", "conditional overflow with kTC noise (seed003-overflow-ktc)",
                        "conditional-overflow pixel with the readout's reset (kTC) noise (120 e⁻ per reset)",
                        ktc_noise=True),
        _frame_entry("seed003-lofic", "lateral overflow 33 ms (seed003-lofic)",
                     "lateral-overflow capacitor pixel, C_S = 500 fF read with the photodiode at low gain, "
                     "33.33 ms at 30 fps", lofic_pixel_parameters,
                     design={"lateral_capacitance_f": 500e-15, "temperature_k": 300.0},
                     exposure_s=seed003_t, frame_rate_hz=30.0),
        _highspeed_entry(),
        _gated_entry(),
    ]
    return {e.name: e for e in entries}


#: Every sensor, by name, in report order.
SENSORS: dict[str, SensorEntry] = _entries()
assert set(SPIKE_PRESET_NAMES) <= set(SENSORS)
assert all(e.family in FAMILIES for e in SENSORS.values())


def sensor_names(*families: str) -> list[str]:
    """Names of the sensors of ``families`` (all when none is given), in catalogue order."""
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
    """
    return entry(name).build(**settings)


def describe(name: str) -> str:
    """One line about sensor ``name``."""
    return entry(name).description
