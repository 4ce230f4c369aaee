"""Design exploration: shoot one scene with a sensor at many settings, score each, find the one that meets demands.

``viform compare`` scores each sensor at its documented settings; a sweep asks the designer's
next question — *at which setting* would a sensor meet the scene's demands, and at what cost.
A sweep is a list of **points** (a comparison sensor key plus the settings that differ from its
default); every point is shot and scored exactly as :mod:`viform.measure.comparison` does it
(same estimates of light, same metrics), so a sweep's default point equals ``viform compare``.

* Parameters (:func:`sweep_parameters`): any numeric or on/off field of the sensor's parameter
  set — the pixel (:class:`~viform.sensors.frame.FramePixelParameters`,
  :class:`~viform.sensors.spike.SpikeSensorParameters`), its optics
  (:class:`~viform.light.radiometry.PixelOptics`), the camera's own settings (exposure, frame
  rate, overflow capacitor …) — plus shorthands: ``threshold_level`` (the spike chip's 16
  threshold levels, seed 000 §6), ``exposure_s`` of the segmented pixel (all segments scaled,
  ratios kept, seed 001 §4), ``first_segment_fraction`` / ``barrier_fraction`` of the
  two-segment pixel (seed 001 fig. 8), the overflow pixel's three integration times (seed 003).
* Value specs (:func:`parse_values`): ``a,b,c``; ``start:stop:step`` (stop included when the
  steps land on it); ``log:start:stop:n`` (n points evenly spaced in log); ``all`` for the
  threshold levels.
* Demands (:func:`parse_require`): ``metric>=bound`` and ``metric<=bound`` joined by commas, on
  the metric names of compare's ``metrics.json``.
* Determinism: each point's noise seed is a pure function of the sweep seed and the point
  (:func:`point_seed`), so results do not depend on the number of workers or their order.
* Resuming: each finished point is written at once (``points/<id>.json`` + ``.npz``,
  atomically); a sweep run again in the same folder — killed, or extended with more points —
  reuses every stored point made with the same scene, size, duration and instants.

Results: ``sweep.zarr`` (one row per point: sensor, point id, every swept parameter's value,
every metric), ``sweep.json`` (the plan, the demands and the answer) and the report
(:mod:`viform.report.sweep_report`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import itertools
import json
import math
import os
import re
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viform._io import atomic_path, write_json
from viform._parallel import open_client, parse_memory
from viform._validate import ViformError, check_int, check_positive, one_line
from viform.measure import comparison as cmp

#: Metrics a sweep scores, with their direction (True: higher is better). The comparison's metrics;
#: scores added to :func:`viform.measure.comparison.score` later (flow, tracking) are stored as
#: extra columns automatically, and become usable in ``--require`` once listed here.
METRIC_DIRECTIONS = {
    "psnr_log_db": True, "ssim_log": True, "saturated_fraction": False, "underexposed_fraction": False,
    "edge_width_px": False, "flicker_error": False, "dr_captured_db": True, "data_rate_mb_per_s": False,
    "latency_s": False, "time_resolution_s": False, "targets_seen": True,
    # tracking of the scene's objects (``--tracking``, scenes with object truth; measure.vision_comparison)
    "tracking_hota": True, "tracking_mota": True, "tracking_idf1": True, "tracking_id_switches": False,
    "tracking_latency_s": False, "tracking_objects_missed": False,
}
#: Contrast-to-noise at which a target counts as seen (as compare's verdict counts it).
SEEN_CNR = 3.0
#: Spike reconstructions a sweep can score (compare's names).
SPIKE_IMAGES = ("best", "interval", "accumulation")
#: Sensor keys a sweep can vary (every comparison sensor).
SWEEP_SENSORS = cmp.DEFAULT_SENSORS
#: Default objective: the best point per sensor is the one closest to the truth.
DEFAULT_OBJECTIVE = "psnr_log_db"
#: Longest clip a sweep shoots, s (each point holds its frames or spikes in memory).
MAX_DURATION_S = 10.0
#: Most bytes of spike clip one point holds in memory (as ``viform compare``).
MAX_SPIKE_BYTES = 2e9
#: Format tag of sweep.json and point records; a change of the scoring bumps the version so old
#: stored points are not reused.
SWEEP_FORMAT, SWEEP_VERSION = "viform-sweep", 1

_OPS = {">=": lambda v, b: v >= b, "<=": lambda v, b: v <= b}


# ---------------------------------------------------------------------- parameters
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
    from viform.measure.comparison import make_compare_sensor

    return make_compare_sensor(key)


def sweep_parameters(key: str) -> dict[str, SweepParameter]:
    """The parameters sensor ``key`` can be swept over, with their defaults (see the module notes)."""
    if key not in SWEEP_SENSORS:
        raise ViformError(f"--sensor: {key!r} is not allowed: choose from {', '.join(SWEEP_SENSORS)}")
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


def make_point_sensor(key: str, settings: dict):
    """The comparison sensor ``key`` with ``settings`` (name → value) applied; errors name ``--vary``."""
    space = sweep_parameters(key)
    unknown = [n for n in settings if n not in space]
    if unknown:
        raise ViformError(f"--vary: {unknown[0]!r} is not a parameter of sensor {key!r}; allowed: "
                          f"{', '.join(sorted(space))}")
    by = {w: {n: v for n, v in settings.items() if space[n].where == w}
          for w in ("pixel", "optics", "camera", "shorthand")}
    base = _base_sensor(key)
    fam = _family(key)
    try:
        return _build(key, fam, base, by)
    except (ViformError, ValueError, TypeError) as exc:
        text = ", ".join(f"{n}={v!r}" for n, v in settings.items())
        raise ViformError(f"--vary: sensor {key!r} at {text} is not a valid setting: {one_line(exc)}") from None


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


# ---------------------------------------------------------------------- specs
def _number(option: str, text: str, kind: str):
    try:
        value = float(text)
    except ValueError:
        raise ViformError(f"{option}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ViformError(f"{option}: {text!r} is not a finite number")
    if kind == "int":
        if value != round(value):
            raise ViformError(f"{option}: {text!r} is not a whole number (the parameter counts)")
        return int(round(value))
    return value


def _bool(option: str, text: str) -> bool:
    t = text.strip().lower()
    if t in ("1", "true", "on", "yes"):
        return True
    if t in ("0", "false", "off", "no"):
        return False
    raise ViformError(f"{option}: {text!r} is not on/off (give true,false)")


def parse_values(option: str, param: SweepParameter, spec: str) -> list:
    """The values of one ``--vary PARAM=SPEC`` (see the module notes); errors name ``option``."""
    spec = spec.strip()
    if not spec:
        raise ViformError(f"{option} gives no values: write PARAM=a,b,c, PARAM=start:stop:step or "
                          "PARAM=log:start:stop:n")
    if param.kind == "bool":
        values = [_bool(option, v) for v in spec.split(",") if v.strip()]
    elif spec == "all" and param.name == "threshold_level":
        from viform.sensors.spike_presets import N_THRESHOLD_LEVELS

        values = list(range(N_THRESHOLD_LEVELS))
    elif spec.startswith("log:"):
        parts = spec[4:].split(":")
        if len(parts) != 3:
            raise ViformError(f"{option}: a log range is log:start:stop:n, not {spec!r}")
        start, stop = (_number(option, p, "float") for p in parts[:2])
        n = _number(option, parts[2], "int")
        if start <= 0 or stop <= 0:
            raise ViformError(f"{option}: a log range needs start and stop > 0, not {spec!r}")
        if n < 1:
            raise ViformError(f"{option}: {spec!r} gives no points (n = {n}); give n ≥ 1")
        values = np.geomspace(start, stop, n).tolist() if n > 1 else [start]
        values = [float(f"{v:.6g}") for v in values]
        if param.kind == "int":
            values = list(dict.fromkeys(int(round(v)) for v in values))
    elif ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise ViformError(f"{option}: a grid is start:stop:step, not {spec!r}")
        start, stop, step = (_number(option, p, param.kind) for p in parts)
        if step <= 0:
            raise ViformError(f"{option}: the step of {spec!r} must be > 0")
        if start > stop:
            raise ViformError(f"{option}: {spec!r} gives no points (start > stop)")
        n = int(math.floor((stop - start) / step * (1 + 1e-9) + 1e-9)) + 1
        if n > 10_000:
            raise ViformError(f"{option}: {spec!r} gives {n} points; at most 10 000 per parameter")
        values = [start + i * step for i in range(n)]
        values = [int(v) for v in values] if param.kind == "int" else [float(f"{v:.12g}") for v in values]
    else:
        values = [_number(option, v.strip(), param.kind) for v in spec.split(",") if v.strip()]
    if not values:
        raise ViformError(f"{option}: {spec!r} gives no points")
    return list(dict.fromkeys(values))


def parse_vary(texts, sensors) -> dict[str, dict[str, list]]:
    """``--vary [SENSOR:]PARAM=SPEC`` options → {sensor: {param: values}}.

    Without ``SENSOR:`` the parameter applies to every sensor of the sweep that has it.
    """
    sensors = list(sensors)
    out: dict[str, dict[str, list]] = {k: {} for k in sensors}
    spaces = {k: sweep_parameters(k) for k in sensors}
    for text in texts or ():
        m = re.fullmatch(r"\s*(?:([\w.-]+):)?([A-Za-z_]\w*)\s*=(.*)", text)
        if m is None:
            raise ViformError(f"--vary {text!r}: write [SENSOR:]PARAM=SPEC, e.g. --vary exposure_s=log:1e-4:1e-2:5")
        who, name, spec = m.group(1), m.group(2), m.group(3)
        option = f"--vary {text.strip()}"
        if who is not None and who not in sensors:
            raise ViformError(f"{option}: sensor {who!r} is not in this sweep (--sensor gives "
                              f"{', '.join(sensors)})")
        targets = [who] if who else [k for k in sensors if name in spaces[k]]
        if not targets:
            allowed = sorted(set().union(*(spaces[k] for k in sensors)))
            raise ViformError(f"{option}: {name!r} is not a parameter of {', '.join(sensors)}; allowed: "
                              f"{', '.join(allowed)}")
        for k in targets:
            if name not in spaces[k]:
                raise ViformError(f"{option}: {name!r} is not a parameter of sensor {k!r}; allowed: "
                                  f"{', '.join(sorted(spaces[k]))}")
            if name in out[k]:
                raise ViformError(f"{option}: {name!r} of sensor {k!r} is already varied by another --vary")
            out[k][name] = parse_values(option, spaces[k][name], spec)
    return out


@dataclass(frozen=True)
class Demand:
    """One demand of ``--require``: ``metric op bound``."""

    metric: str
    op: str
    bound: float

    def met(self, value) -> bool:
        return value is not None and isinstance(value, (int, float)) and math.isfinite(value) \
            and _OPS[self.op](value, self.bound)

    def shortfall(self, value) -> float:
        """How far ``value`` is from meeting the demand (0 when met; inf when not measured)."""
        if value is None or not math.isfinite(value):
            return math.inf
        return max(0.0, self.bound - value) if self.op == ">=" else max(0.0, value - self.bound)

    def text(self) -> str:
        return f"{self.metric}{self.op}{self.bound:g}"


def parse_require(text: str | None) -> list[Demand]:
    """``--require "dr_captured_db>=120,edge_width_px<=2"`` → demands (metric names of compare's metrics.json)."""
    if text is None:
        return []
    demands = []
    parts = [p.strip() for p in text.split(",")]
    if not any(parts):
        raise ViformError("--require is empty: give demands such as dr_captured_db>=120,edge_width_px<=2")
    for part in parts:
        if not part:
            raise ViformError(f"--require {text!r}: an empty demand between commas")
        m = re.fullmatch(r"([A-Za-z_]\w*)\s*(>=|<=)\s*(\S+)", part)
        if m is None:
            raise ViformError(f"--require: {part!r} is not a demand: write METRIC>=NUMBER or METRIC<=NUMBER, "
                              "e.g. dr_captured_db>=120")
        name, op, bound = m.groups()
        if name not in METRIC_DIRECTIONS:
            raise ViformError(f"--require: {name!r} is not a metric; allowed: {', '.join(METRIC_DIRECTIONS)}")
        try:
            value = float(bound)
        except ValueError:
            raise ViformError(f"--require: the bound of {part!r} is not a number") from None
        if not math.isfinite(value):
            raise ViformError(f"--require: the bound of {part!r} is not a finite number")
        demands.append(Demand(name, op, value))
    return demands


def check_objective(name: str) -> str:
    if name not in METRIC_DIRECTIONS:
        raise ViformError(f"--objective: {name!r} is not a metric; allowed: {', '.join(METRIC_DIRECTIONS)}")
    return name


# ---------------------------------------------------------------------- points
def _canonical(value):
    if isinstance(value, bool):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)


@dataclass(frozen=True)
class Point:
    """One sensor at one setting: ``settings`` holds only the parameters that differ from its default."""

    sensor: str
    settings: tuple  # ((name, value), ...) sorted by name
    swept: tuple = ()  # ((name, value), ...) every parameter this sensor's sweep varies, defaults filled in

    @property
    def key(self) -> str:
        return json.dumps([self.sensor, [[n, v] for n, v in self.settings]], separators=(",", ":"))

    @property
    def point_id(self) -> str:
        return hashlib.sha256(self.key.encode()).hexdigest()[:16]

    @property
    def is_default(self) -> bool:
        return not self.settings

    def label(self) -> str:
        if not self.settings:
            return f"{self.sensor} (default)"
        return f"{self.sensor} " + ", ".join(f"{n}={_fmt_value(v)}" for n, v in self.settings)


def _fmt_value(v) -> str:
    return str(v) if isinstance(v, (bool, int)) else f"{v:.4g}"


def point_seed(sweep_seed: int, point: Point) -> int:
    """Noise seed of one point: the first 63 bits of SHA-256("<sweep seed>/<point>") (as dataset clips)."""
    digest = hashlib.sha256(f"{int(sweep_seed)}/{point.key}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)


def plan_points(sensors, vary: dict[str, dict[str, list]]) -> list[Point]:
    """Every point of the sweep: per sensor its default and the grid of its varied parameters.

    A setting equal to the default is dropped from the point (the default point is one point,
    however it is reached). Each point's sensor is built once here, so an invalid setting (an
    exposure longer than the frame period, a threshold level out of range) is refused before
    any work.
    """
    points: dict[str, Point] = {}
    for key in sensors:
        space = sweep_parameters(key)
        grid = vary.get(key, {})
        names = sorted(grid)
        for combo in itertools.product(*(grid[n] for n in names)) if names else [()]:
            settings = {n: _canonical(v) for n, v in zip(names, combo, strict=True)
                        if _canonical(v) != _canonical_default(space[n].default)}
            swept = tuple((n, _canonical(v)) for n, v in zip(names, combo, strict=True))
            p = Point(key, tuple(sorted(settings.items())), swept)
            make_point_sensor(key, settings)
            points.setdefault(p.point_id, p)
        default = Point(key, (), tuple((n, _canonical_default(space[n].default)) for n in names))
        points.setdefault(default.point_id, default)
    return list(points.values())


def _canonical_default(value):
    return None if value is None else _canonical(value)


# ---------------------------------------------------------------------- one point
@dataclass(frozen=True)
class SweepContext:
    """What every point of a sweep shares (stored points are reused only when it matches)."""

    scene: str
    height: int
    width: int
    duration_s: float
    instants_s: tuple
    seed: int
    spike_image: str = "best"
    scene_options: tuple = ()
    tracking: bool = False

    def describe(self) -> dict:
        return {"format": SWEEP_FORMAT, "version": SWEEP_VERSION, **dataclasses.asdict(self),
                "instants_s": list(self.instants_s), "scene_options": dict(self.scene_options)}

    def fingerprint(self) -> str:
        return hashlib.sha256(json.dumps(self.describe(), sort_keys=True).encode()).hexdigest()

    def make_scene(self):
        from viform.light.catalog import BUILTIN_SCENES, builtin_scene, load_scene

        if self.scene in BUILTIN_SCENES:
            return builtin_scene(self.scene, self.height, self.width, **dict(self.scene_options))
        return load_scene(self.scene, self.height, self.width, resize=True,
                          settings={k: list(v) if isinstance(v, tuple) else v for k, v in self.scene_options} or None)


def run_point(context: SweepContext, point: Point) -> dict:
    """Shoot and score one point (runs on a worker); returns its record and its images.

    The record holds the metrics of :func:`viform.measure.comparison.score`; ``images`` holds the
    light estimate (lux, float32; NaN where under-exposed) at each instant, for the report.
    """
    from numba import get_num_threads, set_num_threads

    # CPU of the whole process (numba may run a kernel on its own pool thread): one point at a time per
    # worker process, so this is the point's CPU time (an overestimate when threads share a process)
    started, cpu = time.perf_counter(), time.process_time()
    threads = get_num_threads()
    set_num_threads(1)  # one point per worker: parallelism comes from the workers
    try:
        scene = context.make_scene()
        sensor = make_point_sensor(point.sensor, dict(point.settings))
        seed = point_seed(context.seed, point)
        methods = [context.spike_image] if point.sensor == "spike" else None
        try:
            shots = cmp.shoot(point.sensor, scene, context.duration_s, list(context.instants_s), seed=seed,
                              sensor=sensor, spike_methods=methods)
        except (ViformError, ValueError) as exc:  # this setting cannot shoot this scene (light beyond its range …)
            why = one_line(exc) if isinstance(exc, ViformError) else f"the model refused this light ({one_line(exc)})"
            shots = [cmp.Shot(point.sensor, point.label(), "", skipped=why)]
        shot = shots[0]
        shot.metrics = cmp.score(shot, scene, list(context.instants_s))
    finally:
        set_num_threads(threads)
    metrics = {k: (float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v)
               for k, v in shot.metrics.items()}
    if isinstance(metrics.get("target_cnr"), dict):  # scenes with targets (night-road-fog): how many are seen
        metrics["targets_seen"] = float(sum(v >= SEEN_CNR for v in metrics["target_cnr"].values()))
    if context.tracking and not shot.skipped:
        metrics.update(tracking_scores(scene, context.duration_s, shot))
    images = None
    if not shot.skipped:
        images = np.stack([np.where(e.underexposed, np.nan, np.nan_to_num(np.asarray(e.lux, np.float64)))
                           for e in shot.estimates]).astype(np.float32)
    record = {"point_id": point.point_id, "sensor": point.sensor, "settings": dict(point.settings),
              "swept": dict(point.swept), "default": point.is_default, "label": point.label(),
              "shot_label": shot.label, "skipped": shot.skipped, "seed": seed, "metrics": metrics,
              "context_sha256": context.fingerprint(),
              "seconds": time.perf_counter() - started, "cpu_seconds": time.process_time() - cpu}
    return {"record": record, "images": images}


def tracking_scores(scene, duration_s: float, shot) -> dict:
    """HOTA, MOTA, IDF1, ID switches, median latency and objects never found of the comparison's tracker
    on this shot (:func:`viform.measure.vision_comparison.vision_scores`); {} without object truth.

    Frame cameras' frames are turned into lux with the comparison's inverse response of the sensor at
    its default pixel parameters (exposure and frame times are the shot's own).
    """
    kinds = scene.truth_kinds() if hasattr(scene, "truth_kinds") else ()
    if "objects" not in kinds or shot.key == "gated":
        return {}
    from viform.measure.vision_comparison import vision_scores, vision_table

    rows = [r for r in vision_table(vision_scores({"scene": scene, "duration_s": duration_s, "shots": [shot]}))
            if "skipped" not in r]
    if not rows:
        return {}
    r = rows[0]
    lat = r["median_latency_ms"]
    return {"tracking_hota": float(r["hota"]), "tracking_mota": float(r["mota"]), "tracking_idf1": float(r["idf1"]),
            "tracking_id_switches": float(r["id_switches"]),
            "tracking_latency_s": math.nan if lat is None else lat / 1e3,
            "tracking_objects_missed": float(len(r["never_found"]))}


# ---------------------------------------------------------------------- storage
POINTS_DIR = "points"


def _point_paths(out: Path, point_id: str) -> tuple[Path, Path]:
    return out / POINTS_DIR / f"{point_id}.json", out / POINTS_DIR / f"{point_id}.npz"


def store_point(out: Path, result: dict) -> None:
    """Write one finished point: its images first, then its record (the record marks it finished)."""
    rec = result["record"]
    js, npz = _point_paths(out, rec["point_id"])
    if result["images"] is not None:
        with atomic_path(npz) as tmp, open(tmp, "wb") as f:
            np.savez_compressed(f, lux=result["images"])
    write_json(js, _finite(rec))


def load_point(out: Path, point: Point, context: SweepContext) -> dict | None:
    """The stored record of ``point`` made in this context, or None (missing, other context, damaged)."""
    js, npz = _point_paths(out, point.point_id)
    try:
        rec = json.loads(js.read_text())
    except (OSError, ValueError):
        return None
    if rec.get("context_sha256") != context.fingerprint() or rec.get("point_id") != point.point_id:
        return None
    if not rec.get("skipped") and not npz.is_file():
        return None
    rec["swept"] = dict(point.swept)  # this sweep's axes (a stored point may serve several sweeps)
    return _restore(rec)


def load_images(out: Path, point_id: str) -> np.ndarray | None:
    npz = _point_paths(Path(out), point_id)[1]
    if not npz.is_file():
        return None
    with np.load(npz) as f:
        return f["lux"]


def _finite(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _restore(rec: dict) -> dict:
    rec["metrics"] = {k: (math.nan if v is None and k in METRIC_DIRECTIONS else v) for k, v in rec["metrics"].items()}
    return rec


def metric_columns(records) -> list[str]:
    """Numeric metric columns of a sweep: the known ones first, then any other numeric score."""
    seen = dict.fromkeys(METRIC_DIRECTIONS)
    for r in records:
        for k, v in r["metrics"].items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                seen.setdefault(k)
    return list(seen)


def write_table(path: Path, records, context: SweepContext) -> None:
    """``sweep.zarr``: one row per point (sensor, point_id, label, default, swept parameters, metrics)."""
    import zarr

    cols = metric_columns(records)
    params = sorted({n for r in records for n in r["swept"]})
    with atomic_path(path, directory=True) as tmp:
        root = zarr.open_group(str(tmp), mode="w")
        n = len(records)
        for name, values in (("sensor", [r["sensor"] for r in records]),
                             ("point_id", [r["point_id"] for r in records]),
                             ("label", [r["label"] for r in records])):
            column = root.create_array(name, shape=(n,), dtype=str)  # variable-length UTF-8
            column[:] = np.array(values, dtype=object)
        root.create_array("default", data=np.array([bool(r["default"]) for r in records]))
        for c in cols:
            root.create_array(f"metric/{c}", data=np.array(
                [_as_float(r["metrics"].get(c)) for r in records], dtype=np.float64).reshape(n))
        for p in params:
            root.create_array(f"parameter/{p}", data=np.array(
                [_as_float(r["swept"].get(p)) for r in records], dtype=np.float64).reshape(n))
        root.attrs["viform"] = {**context.describe(), "metrics": cols, "parameters": params,
                                "metric_units": {k: u for k, (_, u) in cmp.METRICS.items()},
                                "note": "one row per point; NaN: not defined for that sensor/scene, or "
                                        "that parameter is not swept for that sensor"}


def read_table(path) -> dict:
    """``sweep.zarr`` back as {column: array} (metric/* and parameter/* keep their prefixes)."""
    import zarr

    root = zarr.open_group(str(path), mode="r")
    out = {k: root[k][:] for k in ("sensor", "point_id", "label", "default")}
    for group in ("metric", "parameter"):
        if group in root:
            for k in root[group].array_keys():
                out[f"{group}/{k}"] = root[group][k][:]
    out["attrs"] = dict(root.attrs)
    return out


def _as_float(v) -> float:
    if v is None or isinstance(v, (dict, list, str)):
        return math.nan
    return float(v)


# ---------------------------------------------------------------------- the answer
def answer(records, demands, objective: str = DEFAULT_OBJECTIVE) -> dict:
    """Which points meet every demand; the best per sensor by ``objective``; else the nearest miss.

    The nearest miss of a sensor is its point that misses the fewest demands, then by the smallest
    sum of relative shortfalls (shortfall / |bound|); a metric not defined for a point misses.
    """
    higher = METRIC_DIRECTIONS.get(objective, True)
    rows = [r for r in records if not r.get("skipped")]
    per_sensor = {}

    def miss_list(r):
        out = []
        for d in demands:
            v = r["metrics"].get(d.metric)
            if not d.met(v):
                out.append({"demand": d.text(), "metric": d.metric, "value": v, "bound": d.bound,
                            "shortfall": d.shortfall(v)})
        return out

    def rank_miss(r):
        misses = miss_list(r)
        rel = sum(m["shortfall"] / max(abs(m["bound"]), 1e-12) for m in misses)
        return (len(misses), rel)

    def objective_value(r):
        v = r["metrics"].get(objective)
        return v if isinstance(v, (int, float)) and math.isfinite(v) else (-math.inf if higher else math.inf)

    for key in dict.fromkeys(r["sensor"] for r in rows):
        mine = [r for r in rows if r["sensor"] == key]
        meeting = [r for r in mine if not miss_list(r)]
        if meeting:
            best = sorted(meeting, key=objective_value, reverse=higher)[0]
            per_sensor[key] = {"meets": True, "best": best["point_id"], "label": best["label"],
                               "settings": best["settings"], "objective": objective_value(best),
                               "n_meeting": len(meeting), "n_points": len(mine)}
        else:
            near = min(mine, key=lambda r: (*rank_miss(r), -objective_value(r) if higher else objective_value(r)))
            per_sensor[key] = {"meets": False, "best": near["point_id"], "label": near["label"],
                               "settings": near["settings"], "objective": objective_value(near),
                               "misses": miss_list(near), "n_meeting": 0, "n_points": len(mine)}
    meeting_ids = [r["point_id"] for r in rows if demands and not miss_list(r)]
    return {"demands": [d.text() for d in demands], "objective": objective, "meeting": meeting_ids,
            "per_sensor": per_sensor, "sentences": answer_sentences(per_sensor, demands, objective)}


def _unit(metric: str) -> str:
    return cmp.METRICS[metric][1] if metric in cmp.METRICS else ""


def _miss_text(m) -> str:
    if not math.isfinite(m["shortfall"]):
        return f"{m['demand']} (not measurable for this sensor here)"
    unit = _unit(m["metric"])
    return (f"{m['demand']} by {m['shortfall']:.3g}{' ' + unit if unit and unit != 'fraction' else ''} "
            f"(it reaches {m['value']:.4g})")


def answer_sentences(per_sensor: dict, demands, objective: str) -> list[str]:
    """The designer's answer in words: who meets the demands at which setting, else the nearest miss."""
    if not per_sensor:
        return ["No point of the sweep could be scored on this scene."]
    if not demands:
        return [f"Best setting of {k} by {objective}: {v['label']} ({objective} = {v['objective']:.4g})."
                for k, v in per_sensor.items()]
    lines = []
    meets = {k: v for k, v in per_sensor.items() if v["meets"]}
    wanted = " and ".join(d.text() for d in demands)
    if meets:
        for k, v in meets.items():
            lines.append(f"{k} meets {wanted} at {_settings_text(v)} ({v['n_meeting']} of {v['n_points']} "
                         f"swept settings do; best by {objective}: {v['objective']:.4g}).")
    else:
        near = min(per_sensor.items(), key=lambda kv: (len(kv[1]["misses"]),
                                                        sum(m["shortfall"] / max(abs(m["bound"]), 1e-12)
                                                            for m in kv[1]["misses"])))
        k, v = near
        lines.append(f"No swept setting meets {wanted}; nearest: {k} at {_settings_text(v)}, which misses "
                     + "; ".join(_miss_text(m) for m in v["misses"]) + ".")
    for k, v in per_sensor.items():
        if not v["meets"] and (meets or k != near[0]):
            lines.append(f"{k}: no swept setting meets them; nearest {_settings_text(v)}, missing "
                         + "; ".join(_miss_text(m) for m in v["misses"]) + ".")
    return lines


def _settings_text(v) -> str:
    if not v["settings"]:
        return "its default setting"
    return ", ".join(f"{n} = {_fmt_value(x)}" for n, x in v["settings"].items())


# ---------------------------------------------------------------------- the sweep
def standard_vary(scene) -> tuple[list[str], dict[str, dict[str, list]]]:
    """The designer's standard sweep: the spike chip's 16 threshold levels × 20/40 kHz, and 20 settings
    of each frame sensor's main knob (exposure; the overflow capacitor; the AE target grey level)."""
    from viform.sensors.spike import CLOCK_20KHZ, CLOCK_40KHZ

    def log20(a, b):
        return [float(f"{v:.4g}") for v in np.geomspace(a, b, 20)]

    vary = {
        "spike": {"threshold_level": list(range(16)), "clock_hz": [CLOCK_20KHZ, CLOCK_40KHZ]},
        "cmos": {"exposure_s": log20(20e-6, 33e-3)},
        "seed001-2seg": {"exposure_s": log20(20e-6, 16e-3)},
        "seed001-3seg": {"exposure_s": log20(20e-6, 16e-3)},
        "seed003-4t": {"exposure_s": log20(20e-6, 33e-3)},
        "seed003-overflow": {"overflow_capacitance_f": log20(20e-15, 20e-12)},
        "highspeed": {"target_gray": [float(v) for v in np.linspace(16, 240, 20).round(1)]},
    }
    if getattr(scene, "active", None) is not None:
        vary["gated"] = {"gate_range_m": [float(v) for v in np.linspace(5, 100, 20).round(2)]}
    return list(vary), vary


def _open(workers, scheduler, memory_limit):
    return open_client(workers, scheduler, parse_memory(memory_limit))


def run_sweep(context: SweepContext, points, out, *, workers: int | None = None, scheduler: str | None = None,
              client=None, memory_limit="auto", progress: bool = True, crash_after_points: int | None = None) -> dict:
    """Run every point not already stored in ``out``; return the records (plan order) and run figures.

    ``workers=0`` runs the points in this process, one after the other (no dask); otherwise on a
    dask LocalCluster of ``workers`` processes (default: the CPU count), on ``scheduler``, or on
    an open ``client``. ``crash_after_points`` (testing aid) ends this process abruptly after
    storing that many new points, as a kill would.
    """
    out = Path(out)
    stored = {p.point_id: load_point(out, p, context) for p in points}
    todo = [p for p in points if stored[p.point_id] is None]
    records = {pid: r for pid, r in stored.items() if r is not None}
    started = time.perf_counter()
    computed = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(points), initial=len(records), unit="point", desc="sweep", leave=False)

    def take(result):
        nonlocal computed
        store_point(out, result)
        rec = _restore(json.loads(json.dumps(_finite(result["record"]))))
        records[rec["point_id"]] = rec
        computed += 1
        if bar is not None:
            bar.update(1)
        if crash_after_points is not None and computed >= crash_after_points:
            os._exit(70)

    n_workers = 0
    own_client = own_cluster = None
    if todo and client is None and workers != 0:  # a scheduler that cannot be reached: nothing written yet
        n = max(1, min(os.cpu_count() or 1, len(todo))) if workers is None else workers
        own_client, own_cluster = _open(n, scheduler, memory_limit)
        client = own_client
    (out / POINTS_DIR).mkdir(parents=True, exist_ok=True)
    try:
        if todo and client is None and workers == 0:
            for p in todo:
                take(run_point(context, p))
        elif todo:
            from distributed import as_completed

            n_workers = len(client.scheduler_info().get("workers", {}))
            token = uuid.uuid4().hex[:8]
            futures = [client.submit(run_point, context, p, key=f"viform-sweep-{p.point_id}-{token}", pure=False)
                       for p in todo]
            for fut in as_completed(futures):
                take(fut.result())
    finally:
        if bar is not None:
            bar.close()
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
    ordered = [records[p.point_id] for p in points]
    new = [r for r in ordered if r["point_id"] in {p.point_id for p in todo}]
    return {"records": ordered, "computed": computed, "reused": len(points) - computed,
            "seconds": time.perf_counter() - started, "workers": n_workers,
            "cpu_seconds": sum(r.get("cpu_seconds", 0.0) for r in new)}


def check_context(out: Path, context: SweepContext) -> None:
    """Refuse an ``--out`` that holds a sweep of another scene, size, duration, instants or seed."""
    path = Path(out) / "sweep.json"
    if not path.is_file():
        return
    try:
        old = json.loads(path.read_text()).get("context", {})
    except (OSError, ValueError):
        return
    new = context.describe()
    if old == json.loads(json.dumps(new)):
        return
    diff = next((k for k in new if old.get(k) != json.loads(json.dumps(new[k]))), "format")
    raise ViformError(f"--out {str(out)!r} holds a sweep made with other settings ({diff}: {old.get(diff)!r} there, "
                      f"{new[diff]!r} now); give a new --out, or the same options to extend or resume it")


def validate_inputs(scene: str, height: int, width: int, duration_s: float, seed: int, instants_s,
                    spike_image: str) -> tuple:
    height = check_int("--height", height, 32, 4096)
    width = check_int("--width", width, 48, 4096)
    seed = check_int("--seed", seed, 0, (1 << 63) - 1)
    check_positive("--duration", duration_s)
    if duration_s > MAX_DURATION_S:
        raise ViformError(f"--duration {duration_s:g} s is not allowed: a sweep shoots the clip once per point "
                          f"and holds it in memory; at most {MAX_DURATION_S:g} s")
    if spike_image not in SPIKE_IMAGES:
        raise ViformError(f"--spike-image: {spike_image!r} is not allowed: choose from {', '.join(SPIKE_IMAGES)}")
    # compare's default instants: 30, 50 and 70 % of the clip
    instants = (tuple(instants_s) if instants_s is not None
                else tuple(float(f"{f * duration_s:.6g}") for f in (0.3, 0.5, 0.7)))
    for t in instants:
        if not 0 <= t < duration_s:
            raise ViformError(f"--at: instant {t!r} s is outside the clip [0, {duration_s:g}) s")
    return height, width, seed, instants


@dataclass
class SweepPlan:
    """A validated sweep: its context, sensors, varied parameters, points and demands."""

    context: SweepContext
    sensors: list
    vary: dict
    points: list
    demands: list = field(default_factory=list)
    objective: str = DEFAULT_OBJECTIVE
    pareto: tuple = (("edge_width_px", "dr_captured_db"), ("data_rate_mb_per_s", "psnr_log_db"))


def make_plan(scene: str, sensors=None, vary_texts=None, *, height: int = 64, width: int = 128,
              duration_s: float = 0.04, seed: int = 0, instants_s=None, require: str | None = None,
              objective: str = DEFAULT_OBJECTIVE, spike_image: str = "best", scene_options: dict | None = None,
              vary: dict | None = None, tracking: bool = False) -> SweepPlan:
    """Validate everything a sweep needs before any work (errors name the flag).

    With no ``sensors`` and no ``vary_texts``: the standard sweep (:func:`standard_vary`).
    ``vary`` (Python API) gives {sensor: {param: values}} directly.
    """
    height, width, seed, instants = validate_inputs(scene, height, width, duration_s, seed, instants_s, spike_image)
    demands = parse_require(require)
    objective = check_objective(objective)
    context = SweepContext(scene, height, width, float(duration_s), tuple(float(t) for t in instants), seed,
                           spike_image, tuple(sorted((scene_options or {}).items())), bool(tracking))
    scene_obj = context.make_scene()
    if tracking and "objects" not in (scene_obj.truth_kinds() if hasattr(scene_obj, "truth_kinds") else ()):
        raise ViformError(f"--tracking: scene {scene!r} has no object truth to score tracking against "
                          "(the built-in scenes have)")
    if sensors is None and not vary_texts and vary is None:
        sensors, vary = standard_vary(scene_obj)
    sensors = list(dict.fromkeys(sensors or (list(vary) if vary else [])))
    if not sensors:
        raise ViformError("--sensor: give at least one sensor, e.g. --sensor spike")
    for k in sensors:
        sweep_parameters(k)
    if "gated" in sensors and getattr(scene_obj, "active", None) is None:
        raise ViformError(f"--sensor gated: the gated camera needs a scene with range (night-road-fog); scene "
                          f"{scene!r} has none")
    if vary is None:
        vary = parse_vary(vary_texts, sensors)
    else:
        spaces = {k: sweep_parameters(k) for k in sensors}
        for k, grid in vary.items():
            for n in grid:
                if n not in spaces.get(k, {}):
                    raise ViformError(f"--vary: {n!r} is not a parameter of sensor {k!r}; allowed: "
                                      f"{', '.join(sorted(spaces.get(k, {})))}")
    if "spike" in sensors:
        clocks = vary.get("spike", {}).get("clock_hz", [cmp.spike_preset()[0].parameters.clock_hz])
        need = height * width * duration_s * max(clocks)
        if need > MAX_SPIKE_BYTES:
            raise ViformError(f"--duration {duration_s:g} s of a {height}×{width} spike clip needs {need / 1e9:.3g} GB "
                              f"in memory per worker, more than {MAX_SPIKE_BYTES / 1e9:g} GB; shorten --duration or "
                              "lower --height/--width")
    points = plan_points(sensors, vary)
    return SweepPlan(context, sensors, vary, points, demands, objective)


def sweep(plan: SweepPlan, out, *, workers: int | None = None, scheduler: str | None = None, client=None,
          memory_limit="auto", progress: bool = True, crash_after_points: int | None = None) -> dict:
    """Run a planned sweep into ``out``: points, ``sweep.zarr`` and ``sweep.json``; returns the sweep document."""
    from viform._io import check_output_folder

    out = Path(out)
    check_output_folder("--out", out)
    if out.exists() and not out.is_dir():
        raise ViformError(f"--out {str(out)!r} is a file, not a folder")
    if scheduler is not None and workers is not None:
        raise ViformError("--workers and --scheduler exclude each other: a scheduler brings its own workers")
    if workers is not None:
        workers = check_int("--workers", workers, 0, 1024)
    check_context(out, plan.context)
    run = run_sweep(plan.context, plan.points, out, workers=workers, scheduler=scheduler, client=client,
                    memory_limit=memory_limit, progress=progress, crash_after_points=crash_after_points)
    records = run["records"]
    result = answer(records, plan.demands, plan.objective)
    write_table(out / "sweep.zarr", records, plan.context)
    doc = {"context": plan.context.describe(), "sensors": plan.sensors,
           "vary": {k: v for k, v in plan.vary.items() if v}, "n_points": len(records),
           "computed": run["computed"], "reused": run["reused"], "seconds": run["seconds"],
           "cpu_seconds": run["cpu_seconds"], "workers": run["workers"], "answer": result,
           "pareto": [list(p) for p in plan.pareto], "points": [_finite(r) for r in records]}
    write_json(out / "sweep.json", _finite(doc))
    doc["records"] = records
    return doc
