"""What a sweep can vary: each sensor's parameters, the scene's, and the sensor at one setting.

A sensor's parameters are its catalogue entry's (:mod:`viform.sensors.catalog`, ``viform sensors
show NAME``: unit, default, allowed values) — a field of the pixel
(:class:`~viform.sensors.frame.FramePixelParameters`, :class:`~viform.sensors.spike.SpikeSensorParameters`),
its optics (:class:`~viform.light.radiometry.PixelOptics`), the camera's own settings (exposure,
frame rate, overflow capacitor …) and the entry's shorthands: ``threshold_level`` (the spike chip's
16 threshold levels, seed 000 §6), ``exposure_s`` of the segmented pixel (all segments scaled, ratios
kept, seed 001 §4), ``first_segment_fraction`` / ``barrier_fraction`` of the two-segment pixel
(seed 001 fig. 8), the overflow pixel's three integration times (seed 003). The sensor at one setting
is the entry's, built as a comparison builds it (:func:`viform.measure.comparison.make_compare_sensor`).
"""

from __future__ import annotations

import numpy as np

from viform._validate import ViformError, one_line
from viform.measure import comparison as cmp
from viform.sensors.catalog import SENSORS, Parameter

#: Sensors a sweep shoots when none is named (compare's); any sensor of the catalogue can be swept.
SWEEP_SENSORS = cmp.DEFAULT_SENSORS


def _scalar_kind(value) -> str | None:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, np.integer)):
        return "int"
    if isinstance(value, (float, np.floating)):
        return "float"
    return None


def check_sensor(key: str, name: str = "key") -> str:
    """``key`` when it is a sensor of the catalogue a sweep can shoot (a name that changed meaning,
    :data:`viform.measure.comparison.RENAMED`, is refused with where it went); the error begins with ``name``."""
    if key in cmp.RENAMED:
        raise ViformError(f"{name}: {key!r} is not a sensor a sweep can vary: {cmp.RENAMED[key]}")
    if key not in SENSORS:
        allowed = [n for n in SENSORS if n not in cmp.RENAMED]
        raise ViformError(f"{name}: {key!r} is not a sensor a sweep can vary: choose from {', '.join(allowed)}")
    return key


def sweep_parameters(key: str, name: str = "key") -> dict[str, Parameter]:
    """The parameters sensor ``key`` can be swept over, with their defaults: its catalogue entry's
    (:mod:`viform.sensors.catalog`); an unknown ``key`` is refused with an error that begins with ``name``."""
    return cmp.compare_entry(check_sensor(key, name)).parameters


def make_point_sensor(key: str, settings: dict, name: str = "settings"):
    """The comparison sensor ``key`` with ``settings`` (parameter → value) applied.

    Errors begin with ``name``, the caller's name for the settings (:func:`~viform.measure.sweep.make_plan`
    passes ``"vary"``).
    """
    space = sweep_parameters(key)
    unknown = [n for n in settings if n not in space]
    if unknown:
        raise ViformError(f"{name}: {unknown[0]!r} is not a parameter of sensor {key!r}; allowed: "
                          f"{', '.join(sorted(space))}")
    try:
        return cmp.make_compare_sensor(key, **settings)
    except (ViformError, ValueError, TypeError) as exc:
        text = ", ".join(f"{n}={v!r}" for n, v in settings.items())
        raise ViformError(f"{name}: sensor {key!r} at {text} is not a valid setting: {one_line(exc)}") from None


#: Units of a scene parameter, by the ending of its name (names carry their units).
_UNIT_ENDINGS = (("_px_per_s", "px/s"), ("_lux", "lux"), ("_hz", "Hz"), ("_s", "s"), ("_m", "m"))


def _scene_parameter(name: str, default, doc: str) -> Parameter | None:
    kind = _scalar_kind(default)
    unit = next((u for end, u in _UNIT_ENDINGS if name.endswith(end)), "")
    return None if kind is None else Parameter(name, kind, default, unit=unit, where="scene", doc=doc)


def scene_parameters(scene: str) -> dict[str, Parameter]:
    """The numeric and on/off parameters of ``scene`` a sweep can vary (``scene:NAME=SPEC``), with defaults.

    A built-in scene: its constructor's parameters (:data:`viform.light.catalog.SCENES`) and the
    settings every scene takes where it maps them — ``brightness`` (a factor on its light),
    ``peak_lux`` (its brightest level, lux) and ``speed`` (a factor on its motion). A scene
    description: its declared parameters and those three. An image or video: none.
    """
    from viform.light.catalog import BUILTIN_SCENES, SCENES
    from viform.light.description import UNIVERSAL_SETTINGS, is_description_file, load_description

    out: dict[str, Parameter] = {}
    if scene in BUILTIN_SCENES:
        entry = SCENES[scene]
        universal = {"brightness": entry.brightness is not None, "peak_lux": entry.brightness is not None,
                     "speed": entry.speed is not None}
        declared = {n: (v, "") for n, v in entry.parameters.items()}
    elif is_description_file(scene):
        universal = dict.fromkeys(UNIVERSAL_SETTINGS, True)
        params = load_description(scene).get("parameters") or {}
        declared = {n: (spec.get("value", spec.get("default")), spec.get("description", ""))
                    for n, spec in params.items() if isinstance(spec, dict)}
    else:
        return out
    for name, ok in universal.items():
        if ok:
            out[name] = Parameter(name, "float", None if name == "peak_lux" else 1.0,
                                  unit="lux" if name == "peak_lux" else "", where="scene", doc=UNIVERSAL_SETTINGS[name])
    for name, (default, doc) in declared.items():
        p = _scene_parameter(name, default, doc)
        if p is not None and name not in out:
            out[name] = p
    return out
