"""What a sweep can vary: each sensor's parameters, and the sensor at one setting.

A parameter is any numeric or on/off field of the sensor's parameter set — the pixel
(:class:`~viform.sensors.frame.FramePixelParameters`, :class:`~viform.sensors.spike.SpikeSensorParameters`),
its optics (:class:`~viform.light.radiometry.PixelOptics`), the camera's own settings (exposure,
frame rate, overflow capacitor …) — plus shorthands: ``threshold_level`` (the spike chip's 16
threshold levels, seed 000 §6), ``exposure_s`` of the segmented pixel (all segments scaled, ratios
kept, seed 001 §4), ``first_segment_fraction`` / ``barrier_fraction`` of the two-segment pixel
(seed 001 fig. 8), the overflow pixel's three integration times (seed 003).
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_positive, one_line
from viform.measure import comparison as cmp

#: Sensor keys a sweep can vary (every comparison sensor).
SWEEP_SENSORS = cmp.DEFAULT_SENSORS


@dataclass(frozen=True)
class SweepParameter:
    """One parameter a sweep can vary: its name, kind ("float", "int" or "bool") and default value."""

    name: str
    kind: str
    default: object
    where: str  # "pixel", "optics", "camera" or "shorthand" (how it is applied)
    doc: str = ""


def _scalar_kind(value) -> str | None:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, np.integer)):
        return "int"
    if isinstance(value, (float, np.floating)):
        return "float"
    return None


def _dataclass_scalars(obj, where: str, skip=()) -> dict[str, SweepParameter]:
    out = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        kind = _scalar_kind(value)
        if kind is not None and f.name not in skip:
            out[f.name] = SweepParameter(f.name, kind, value, where)
    return out


def _constructor_scalars(sensor, skip=()) -> dict[str, SweepParameter]:
    """Scalar arguments of the sensor's constructor that the object keeps under the same name."""
    out = {}
    for name in inspect.signature(type(sensor).__init__).parameters:
        if name in ("self", "parameters", "height", "width") or name in skip or not hasattr(sensor, name):
            continue
        value = getattr(sensor, name)
        kind = _scalar_kind(value)
        if kind is not None:
            out[name] = SweepParameter(name, kind, value, "camera")
    return out


def _family(key: str) -> str:
    return {"spike": "spike", "highspeed": "highspeed", "gated": "gated", "seed001-2seg": "segmented",
            "seed001-3seg": "segmented", "seed003-overflow": "overflow"}.get(key, "frame")


def _base_sensor(key: str):
    return cmp.make_compare_sensor(key)


def check_sensor(key: str, name: str = "key") -> str:
    """``key`` when it is a sensor a sweep can vary (:data:`SWEEP_SENSORS`); the error names ``name``."""
    if key not in SWEEP_SENSORS:
        raise ViformError(f"{name}: {key!r} is not a sensor a sweep can vary: choose from {', '.join(SWEEP_SENSORS)}")
    return key


def sweep_parameters(key: str) -> dict[str, SweepParameter]:
    """The parameters sensor ``key`` can be swept over, with their defaults (see the module notes)."""
    check_sensor(key)
    base = _base_sensor(key)
    fam = _family(key)
    params: dict[str, SweepParameter] = {}
    if fam == "spike":
        from viform.sensors.spike_presets import N_THRESHOLD_LEVELS, threshold_levels_electrons

        p = base.parameters
        levels = threshold_levels_electrons()
        default_level = next((k for k, q in enumerate(levels) if q == p.threshold_electrons), None)
        params["threshold_level"] = SweepParameter(
            "threshold_level", "int", default_level, "shorthand",
            f"the chip's threshold level 0…{N_THRESHOLD_LEVELS - 1} (Q = (level + 1)·1 250 e⁻)")
        params.update(_dataclass_scalars(p, "pixel"))
        params.update(_dataclass_scalars(p.optics, "optics"))
        return params
    if fam == "highspeed":
        params.update(_dataclass_scalars(base, "camera", skip=("n_frames", "seed", "scene_samples")))
        params.update(_dataclass_scalars(base.pixel_parameters, "pixel"))
        params.update(_dataclass_scalars(base.pixel_parameters.optics, "optics"))
        return params
    if fam == "gated":
        params["pulses"] = SweepParameter("pulses", "int", base.pulses, "camera")
        params["gate_range_m"] = SweepParameter("gate_range_m", "float", cmp.GATED_RANGE_M, "camera")
        params["frame_rate_hz"] = SweepParameter("frame_rate_hz", "float", base.frame_rate_hz, "camera")
        return params
    params.update(_constructor_scalars(base))
    if fam in ("frame", "segmented"):
        params["exposure_s"] = SweepParameter("exposure_s", "float", base.exposure_s,
                                              "camera" if fam == "frame" else "shorthand",
                                              "total exposure, s" + (" (segments scaled, ratios kept)"
                                                                     if fam == "segmented" else ""))
    if fam == "segmented" and len(base.segment_times_s) == 2:
        t = base.segment_times_s
        params["first_segment_fraction"] = SweepParameter(
            "first_segment_fraction", "float", t[0] / sum(t), "shorthand", "T1 / (T1 + T2)")
        params["barrier_fraction"] = SweepParameter(
            "barrier_fraction", "float", base.clamp_levels_electrons[0] / base.parameters.full_well_electrons,
            "shorthand", "barrier B1 / full well")
    if fam == "overflow":
        for name, value in zip(("long_integration_s", "medium_integration_s", "short_integration_s"),
                               base.integration_times_s, strict=True):
            params[name] = SweepParameter(name, "float", value, "shorthand", "one of the three integrations, s")
    params.update(_dataclass_scalars(base.parameters, "pixel"))
    params.update(_dataclass_scalars(base.parameters.optics, "optics"))
    return params


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
    by = {w: {n: v for n, v in settings.items() if space[n].where == w}
          for w in ("pixel", "optics", "camera", "shorthand")}
    base = _base_sensor(key)
    fam = _family(key)
    try:
        return _build(key, fam, base, by)
    except (ViformError, ValueError, TypeError) as exc:
        text = ", ".join(f"{n}={v!r}" for n, v in settings.items())
        raise ViformError(f"{name}: sensor {key!r} at {text} is not a valid setting: {one_line(exc)}") from None


def _with_pixel(pixel, by):
    optics = dataclasses.replace(pixel.optics, **by["optics"]) if by["optics"] else pixel.optics
    return dataclasses.replace(pixel, optics=optics, **by["pixel"])


def _build(key, fam, base, by):
    from viform.sensors.spike import SpikeSensor

    if fam == "spike":
        short = dict(by["shorthand"])
        pixel = dict(by["pixel"])
        if "threshold_level" in short:
            if "threshold_electrons" in pixel:
                raise ViformError("give either threshold_level or threshold_electrons, not both")
            from viform.sensors.spike_presets import threshold_level_electrons

            pixel["threshold_electrons"] = threshold_level_electrons(short["threshold_level"])
        params = _with_pixel(base.parameters, {**by, "pixel": pixel})
        return SpikeSensor(params, base.height, base.width)
    if fam == "highspeed":
        pixel = _with_pixel(base.pixel_parameters, by)
        return dataclasses.replace(base, pixel_parameters=pixel, **by["camera"])
    if fam == "gated":
        from viform.sensors.gated_ccd import GatedInterlineCCD

        kw = {"pulses": base.pulses, "gate_range_m": cmp.GATED_RANGE_M, "frame_rate_hz": base.frame_rate_hz}
        return GatedInterlineCCD(**{**kw, **by["camera"]})
    pixel = _with_pixel(base.parameters, by)
    kw = {n: getattr(base, n) for n in inspect.signature(type(base).__init__).parameters
          if n not in ("self", "parameters", "height", "width") and hasattr(base, n)}
    kw.update(by["camera"])
    short = by["shorthand"]
    if fam == "segmented":
        times = np.asarray(base.segment_times_s, dtype=np.float64)
        levels = np.asarray(base.clamp_levels_electrons, dtype=np.float64) / base.parameters.full_well_electrons
        total = float(short.get("exposure_s", times.sum()))
        check_positive("exposure_s", total)
        if "first_segment_fraction" in short:
            f = float(short["first_segment_fraction"])
            if not 0 < f < 1:
                raise ViformError(f"first_segment_fraction = {f!r} must lie strictly between 0 and 1")
            times = np.array([f, 1 - f])
        if "barrier_fraction" in short:
            levels = np.array([float(short["barrier_fraction"])])
        times = times / times.sum() * total
        kw["segment_times_s"] = tuple(times.tolist())
        kw["clamp_levels_electrons"] = tuple((levels * pixel.full_well_electrons).tolist())
    if fam == "overflow":
        times = list(base.integration_times_s)
        for i, name in enumerate(("long_integration_s", "medium_integration_s", "short_integration_s")):
            if name in short:
                times[i] = float(short[name])
        kw["integration_times_s"] = tuple(times)
    return type(base)(pixel, **kw)


def _scene_parameter(name: str, default, doc: str) -> SweepParameter | None:
    kind = _scalar_kind(default)
    return None if kind is None else SweepParameter(name, kind, default, "scene", doc)


def scene_parameters(scene: str) -> dict[str, SweepParameter]:
    """The numeric and on/off parameters of ``scene`` a sweep can vary (``scene:NAME=SPEC``), with defaults.

    A built-in scene: its constructor's parameters (:data:`viform.light.catalog.SCENES`) and the
    settings every scene takes where it maps them — ``brightness`` (a factor on its light),
    ``peak_lux`` (its brightest level, lux) and ``speed`` (a factor on its motion). A scene
    description: its declared parameters and those three. An image or video: none.
    """
    from viform.light.catalog import BUILTIN_SCENES, SCENES
    from viform.light.description import UNIVERSAL_SETTINGS, is_description_file, load_description

    out: dict[str, SweepParameter] = {}
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
            out[name] = SweepParameter(name, "float", None if name == "peak_lux" else 1.0, "scene",
                                       UNIVERSAL_SETTINGS[name])
    for name, (default, doc) in declared.items():
        p = _scene_parameter(name, default, doc)
        if p is not None and name not in out:
            out[name] = p
    return out
