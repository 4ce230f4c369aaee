"""A sweep's plan: what every point shares (the context), the points, and the validated whole.

* A point (:class:`Point`) is a comparison sensor plus the settings that differ from its default.
* Determinism: each point's noise seed is a pure function of the sweep seed and the point
  (:func:`point_seed`), so results do not depend on the number of workers or their order.
* :func:`make_plan` validates everything before any work; its errors begin with the name of the
  parameter they are about.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
from dataclasses import dataclass, field

import numpy as np

from viform._validate import ViformError, check_int, check_positive, one_line, size_text
from viform.measure import comparison as cmp
from viform.measure.sweep.parameters import check_sensor, make_point_sensor, scene_parameters, sweep_parameters
from viform.measure.sweep.specs import DEFAULT_OBJECTIVE, SCENE, check_objective, parse_require, parse_vary

#: Spike reconstructions a sweep can score (compare's names).
SPIKE_IMAGES = ("best", "interval", "accumulation")
#: Longest clip a sweep shoots, s (each point holds its frames or spikes in memory).
MAX_DURATION_S = 10.0
#: Most bytes of spike clip one point holds in memory (as ``viform compare``).
MAX_SPIKE_BYTES = 2e9
#: Format tag of sweep.json and point records; a change of the scoring bumps the version so old
#: stored points are not reused.
SWEEP_FORMAT, SWEEP_VERSION = "viform-sweep", 2


def _canonical(value):
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)


def _canonical_default(value):
    return None if value is None else _canonical(value)


def _fmt_value(v) -> str:
    return str(v) if isinstance(v, (bool, int)) else f"{v:.4g}"


#: Prefix of a varied scene parameter among a point's swept parameters and the table's columns.
SCENE_PREFIX = "scene."


@dataclass(frozen=True)
class Point:
    """One sensor at one setting (``settings``: only the parameters that differ from its default), on
    the scene at ``scene`` (the varied scene parameters, every value kept; empty when none is varied)."""

    sensor: str
    settings: tuple  # ((name, value), ...) sorted by name
    swept: tuple = ()  # ((name, value), ...) every parameter this sensor's sweep varies, defaults filled in
    scene: tuple = ()  # ((name, value), ...) sorted by name: the scene's varied parameters

    @property
    def key(self) -> str:
        parts = [self.sensor, [[n, v] for n, v in self.settings]]
        if self.scene:  # a point on the sweep's own scene keeps the key (and the seed) it always had
            parts.append([[n, v] for n, v in self.scene])
        return json.dumps(parts, separators=(",", ":"))

    @property
    def point_id(self) -> str:
        return hashlib.sha256(self.key.encode()).hexdigest()[:16]

    @property
    def is_default(self) -> bool:
        return not self.settings

    def label(self) -> str:
        text = (f"{self.sensor} (default)" if not self.settings
                else f"{self.sensor} " + ", ".join(f"{n}={_fmt_value(v)}" for n, v in self.settings))
        if self.scene:
            text += " · scene " + ", ".join(f"{n}={_fmt_value(v)}" for n, v in self.scene)
        return text


#: Cameras that a sweep knew under another name, by the name that seeds their points: a renamed
#: camera keeps the noise of every point (the same bits at the same settings and sweep seed).
SEEDED_AS = {"spikeone": "spike"}


def point_seed(sweep_seed: int, point: Point) -> int:
    """Noise seed of one point: the first 63 bits of SHA-256("<sweep seed>/<point>") (as dataset clips),
    the point written with its sensor's seeding name (:data:`SEEDED_AS`)."""
    key = dataclasses.replace(point, sensor=SEEDED_AS.get(point.sensor, point.sensor)).key
    digest = hashlib.sha256(f"{int(sweep_seed)}/{key}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)


def plan_points(sensors, vary: dict[str, dict[str, list]], name: str = "vary") -> list[Point]:
    """Every point of the sweep: per sensor its default and the grid of its varied parameters.

    A setting equal to the default is dropped from the point (the default point is one point,
    however it is reached). Each point's sensor is built once here, so an invalid setting (an
    exposure longer than the frame period, a threshold level out of range) is refused before
    any work; the error begins with ``name``.
    """
    points: dict[str, Point] = {}
    for scene in scene_settings(vary):
        scene_swept = tuple((SCENE_PREFIX + n, v) for n, v in scene)
        for key in sensors:
            space = sweep_parameters(key)
            grid = vary.get(key, {})
            names = sorted(grid)
            for combo in itertools.product(*(grid[n] for n in names)) if names else [()]:
                settings = {n: _canonical(v) for n, v in zip(names, combo, strict=True)
                            if _canonical(v) != _canonical_default(space[n].default)}
                swept = tuple((n, _canonical(v)) for n, v in zip(names, combo, strict=True))
                p = Point(key, tuple(sorted(settings.items())), swept + scene_swept, scene)
                if p.point_id not in points:
                    make_point_sensor(key, settings, name)
                points.setdefault(p.point_id, p)
            default = Point(key, (), tuple((n, _canonical_default(space[n].default)) for n in names) + scene_swept,
                            scene)
            points.setdefault(default.point_id, default)
    return list(points.values())


def scene_settings(vary: dict) -> list[tuple]:
    """Every combination of the varied scene parameters (``vary["scene"]``), each ((name, value), ...)
    sorted by name; [()] when the scene is not varied."""
    grid = vary.get(SCENE, {}) or {}
    names = sorted(grid)
    return [tuple(zip(names, (_canonical(v) for v in combo), strict=True))
            for combo in itertools.product(*(grid[n] for n in names))] if names else [()]


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

    def make_scene(self, settings=()):
        """The scene, with ``settings`` (varied scene parameters, name → value) on top of its options."""
        from viform.light.catalog import BUILTIN_SCENES, builtin_scene, entry_settings, load_scene

        varied = dict(settings)
        if self.scene in BUILTIN_SCENES:
            options = dict(self.scene_options)
            if varied:  # the options are the scene's own keywords; the varied settings apply on top of them
                options = entry_settings(self.scene, {**options, **varied}, "scene setting")
            return builtin_scene(self.scene, self.height, self.width, **options)
        base = {k: list(v) if isinstance(v, tuple) else v for k, v in self.scene_options}
        return load_scene(self.scene, self.height, self.width, resize=True, settings={**base, **varied} or None)


def standard_vary(scene) -> tuple[list[str], dict[str, dict[str, list]]]:
    """The designer's standard sweep: the spike chip's 16 threshold levels × 20/40 kHz, and 20 settings
    of each frame sensor's main knob (exposure; the overflow capacitor; the AE target grey level)."""
    from viform.sensors.spike import CLOCK_20KHZ, CLOCK_40KHZ

    def log20(a, b):
        return [float(f"{v:.4g}") for v in np.geomspace(a, b, 20)]

    vary = {
        "spikeone": {"threshold_level": list(range(16)), "clock_hz": [CLOCK_20KHZ, CLOCK_40KHZ]},
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


def validate_inputs(scene: str, height: int, width: int, duration_s: float, seed: int, instants_s,
                    spike_image: str) -> tuple:
    """(height, width, seed, instants_s) checked; errors begin with the parameter's name."""
    height = check_int("height", height, 32, 4096)
    width = check_int("width", width, 48, 4096)
    seed = check_int("seed", seed, 0, (1 << 63) - 1)
    check_positive("duration_s", duration_s)
    if duration_s > MAX_DURATION_S:
        raise ViformError(f"duration_s = {duration_s:g} s is not allowed: a sweep shoots the clip once per point "
                          f"and holds it in memory; at most {MAX_DURATION_S:g} s")
    if spike_image not in SPIKE_IMAGES:
        raise ViformError(f"spike_image = {spike_image!r} is not allowed: choose from {', '.join(SPIKE_IMAGES)}")
    # compare's default instants: 30, 50 and 70 % of the clip
    instants = (tuple(instants_s) if instants_s is not None
                else tuple(float(f"{f * duration_s:.6g}") for f in (0.3, 0.5, 0.7)))
    for t in instants:
        if not 0 <= t < duration_s:
            raise ViformError(f"instants_s: instant {t!r} s is outside the clip [0, {duration_s:g}) s")
    return height, width, seed, instants


def check_scene_settings(context: SweepContext, vary: dict, tracking: bool = False, name: str = "vary") -> None:
    """Build the scene at every combination of its varied parameters, so a value it refuses is refused
    before any work (and, with ``tracking``, one without objects); a parameter also set in the
    context's scene options is refused (give it in one place)."""
    grid = vary.get(SCENE) or {}
    both = sorted(set(grid) & {k for k, _ in context.scene_options})
    if both:
        raise ViformError(f"{name}: the scene's {both[0]!r} is both varied and set in scene_options; give it in "
                          "one place")
    for settings in scene_settings(vary) if grid else ():
        text = ", ".join(f"{n}={_fmt_value(v)}" for n, v in settings)
        try:
            scene_obj = context.make_scene(settings)
        except (ViformError, ValueError, TypeError) as exc:
            raise ViformError(f"{name}: the scene at {text} cannot be made: {one_line(exc)}") from None
        if tracking:
            try:
                check_objects(scene_obj, context.scene, context.duration_s, context.instants_s, name)
            except ViformError as exc:
                raise ViformError(f"{exc} (at {text})") from None


def check_objects(scene_obj, scene: str, duration_s: float, instants_s=(), name: str = "tracking") -> None:
    """Refuse to score tracking on a scene without objects to track in the clip: no object truth, or an
    object truth that is empty at 16 instants spread over the clip and at ``instants_s``."""
    if "objects" not in (scene_obj.truth_kinds() if hasattr(scene_obj, "truth_kinds") else ()):
        raise ViformError(f"{name}: scene {scene!r} has no object truth to score tracking against; give a scene "
                          "with objects (e.g. multi-object)")
    times = sorted({*(float(t) for t in np.linspace(0.0, duration_s, 16, endpoint=False)), *map(float, instants_s)})
    if not any(len(scene_obj.objects(t)) for t in times):
        raise ViformError(f"{name}: scene {scene!r} has no objects to track in the {duration_s * 1e3:g} ms clip (its "
                          "object truth is empty), so every tracking score would be 0 of nothing; give a scene "
                          "with objects (e.g. multi-object, dilemma, waving-hand)")


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
    """Validate everything a sweep needs before any work; errors begin with the parameter's name.

    With no ``sensors`` and no ``vary_texts``: the standard sweep (:func:`standard_vary`).
    ``vary_texts`` are ``[SENSOR:]PARAM=SPEC`` texts (:func:`~viform.measure.sweep.specs.parse_vary`);
    ``vary`` gives {sensor: {param: values}} directly instead.

    Parameters
    ----------
    scene : str
        A scene of the catalogue or a scene file (:func:`~viform.light.catalog.load_scene`).
    sensors : sequence of str, optional
        Catalogue sensors to sweep (:data:`SWEEP_SENSORS`).
    vary_texts : sequence of str, optional
        ``[SENSOR:]PARAM=SPEC`` texts (``exposure_s=log:1e-4:1e-2:5``).
    height, width : int
        Scene size, pixels.
    duration_s : float
        Length of each capture, s.
    seed : int
        Seed of the points' noise (each point's own seed derives from it).
    instants_s : sequence of float, optional
        Instants scored, s (default: 30, 50 and 70 % of the capture, as ``compare``).
    require : str, optional
        Demands, ``METRIC<=VALUE`` joined by commas (``edge_width_px<=2``).
    objective : str
        The metric that ranks the settings that meet the demands.
    spike_image : str
        The spike reconstruction scored, of :data:`SPIKE_IMAGES` (``"best"``: the best one per point).
    scene_options : dict, optional
        The scene's own settings.
    vary : dict, optional
        {sensor: {parameter: values}}, instead of ``vary_texts``.
    tracking : bool
        Also score tracking (the scene must have objects to track in the clip).

    Returns
    -------
    SweepPlan
        The points, the demands and the context a sweep runs and resumes by.
    """
    height, width, seed, instants = validate_inputs(scene, height, width, duration_s, seed, instants_s, spike_image)
    demands = parse_require(require)
    objective = check_objective(objective)
    context = SweepContext(scene, height, width, float(duration_s), tuple(float(t) for t in instants), seed,
                           spike_image, tuple(sorted((scene_options or {}).items())), bool(tracking))
    scene_obj = context.make_scene()
    if tracking:
        check_objects(scene_obj, scene, context.duration_s, context.instants_s)
    if sensors is None and not vary_texts and vary is None:
        sensors, vary = standard_vary(scene_obj)
    sensors = list(dict.fromkeys(sensors or (list(vary) if vary else [])))
    if not sensors:
        raise ViformError("sensors: give at least one sensor, e.g. ['spikeone']")
    for k in sensors:
        check_sensor(k, "sensors")
    gated = [k for k in sensors if cmp.compare_entry(k).family == "gated"]
    if gated and getattr(scene_obj, "active", None) is None:
        raise ViformError(f"sensors: {gated[0]!r} needs a scene with range (night-road-fog); scene {scene!r} has none")
    scene_space = scene_parameters(scene)
    if vary is None:
        vary = parse_vary(vary_texts, sensors, scene_space)
    else:
        spaces = {k: sweep_parameters(k) for k in sensors}
        spaces[SCENE] = scene_space
        for k, grid in vary.items():
            if k not in spaces:
                raise ViformError(f"vary: {k!r} is not a sensor of this sweep (its sensors: {', '.join(sensors)}) "
                                  f"nor {SCENE!r}")
            for n in grid:
                if n not in spaces[k]:
                    raise ViformError(f"vary: {n!r} is not a parameter of {'the scene' if k == SCENE else k!r}; "
                                      f"allowed: {', '.join(sorted(spaces[k])) or 'none'}")
    check_scene_settings(context, vary, tracking)
    for k in sensors:
        if cmp.compare_entry(k).family != "spike":
            continue
        clocks = vary.get(k, {}).get("clock_hz", [sweep_parameters(k)["clock_hz"].default])
        need = height * width * duration_s * max(clocks)
        if need > MAX_SPIKE_BYTES:
            raise ViformError(f"duration_s = {duration_s:g} s of a {size_text(height, width)} spike clip needs "
                              f"{need / 1e9:.3g} "
                              f"GB in memory per worker, more than {MAX_SPIKE_BYTES / 1e9:g} GB; shorten the clip or "
                              "lower the resolution")
    points = plan_points(sensors, vary)
    return SweepPlan(context, sensors, vary, points, demands, objective)
