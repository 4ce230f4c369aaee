"""A sensor's parameters by name, as users set them: kind, unit, default and allowed range.

:class:`Parameter` is one parameter of a catalogue entry (:mod:`viform.sensors.catalog`); the helpers
read them off a model — the fields of its parameter dataclasses, the keyword arguments of its
constructor — with units from the names (``_s``, ``_hz``, ``_electrons`` …) and ranges from
:data:`_RANGES` (a test checks each against the model's own validation).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError
from viform.sensors.auto_exposure import METERS
from viform.sensors.gated_waveforms import DRIVES
from viform.sensors.spike_presets import N_THRESHOLD_LEVELS

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
#: Allowed ranges that differ from "a finite number > 0" (float) or "≥ 0" (int): (low, high, low_open, high_open);
#: None for no bound; by name, or by (part, name) where two parts use one name differently. The model's own
#: validation stays in force (cross-parameter limits, e.g. an exposure within the frame period); a test checks
#: that each bound here is one the model enforces.
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
        return value_text(self.default)


def _unit(name: str) -> str:
    if name in _NAME_UNITS:
        return _NAME_UNITS[name]
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def parameter_for(name: str, default, where: str, field_name: str | None = None, doc: str = "",
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


def fields_of(obj, where: str, prefix: str = "", skip=(), docs: dict | None = None) -> dict[str, Parameter]:
    """Every field of the dataclass ``obj`` (scalars, text) as parameters, named ``prefix + field``."""
    out = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.name in skip or dataclasses.is_dataclass(value) or isinstance(value, (tuple, list, dict)):
            continue
        name = prefix + f.name
        optional = value is None or f.default is None
        out[name] = parameter_for(name, value, where, f.name, (docs or {}).get(f.name, ""), optional=optional,
                               kind="float" if value is None else None)
    return out


def arguments_of(cls, defaults: dict, skip=()) -> dict[str, Parameter]:
    """The keyword arguments of ``cls``'s constructor (scalars, text) as "camera" parameters."""
    out = {}
    for name, p in inspect.signature(cls.__init__).parameters.items():
        if name in ("self", "parameters", "height", "width") or name in skip or p.kind is p.VAR_KEYWORD:
            continue
        value = defaults.get(name, p.default)
        if value is inspect.Parameter.empty or isinstance(value, (tuple, list)) or dataclasses.is_dataclass(value):
            continue
        out[name] = parameter_for(name, value, "camera", optional=value is None or p.default is None,
                               kind="float" if value is None else None)
    return out


def merged(*groups: dict) -> dict[str, Parameter]:
    """One namespace of parameters: a name given by two parts of a model is an error of the catalogue."""
    out: dict[str, Parameter] = {}
    for group in groups:
        for name, p in group.items():
            if name in out:
                raise AssertionError(f"parameter {name!r} is both {out[name].where} and {p.where}: prefix one")
            out[name] = p
    return out


def value_text(v) -> str:
    """A parameter's value as users type it after ``--set NAME=``: none, true/false, 6 digits."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)
