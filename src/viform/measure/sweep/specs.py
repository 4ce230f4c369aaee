"""What a sweep is told in text: value specs of a parameter, the demands, the objective.

* Value specs (:func:`parse_values`): ``a,b,c``; ``start:stop:step`` (stop included when the steps
  land on it); ``log:start:stop:n`` (n points evenly spaced in log); ``true,false`` for on/off
  parameters; ``all`` for the threshold levels.
* Varied parameters (:func:`parse_vary`): ``[SENSOR:]PARAM=SPEC``, and ``scene:PARAM=SPEC`` for a
  parameter of the scene.
* Demands (:func:`parse_require`): ``metric>=bound`` and ``metric<=bound`` joined by commas, on the
  metric names of :data:`METRIC_DIRECTIONS`.

Every error begins with the name of the parameter it is about (the caller's name for it), so
a command can name its own flag instead.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError
from viform.measure.sweep.parameters import sweep_parameters
from viform.sensors.catalog import Parameter

#: Metrics a sweep scores, with their direction (True: higher is better). The comparison's metrics;
#: scores added to :func:`viform.measure.comparison.score` later (flow, tracking) are stored as
#: extra columns automatically, and become usable in demands once listed here.
METRIC_DIRECTIONS = {
    "psnr_log_db": True, "ssim_log": True, "saturated_fraction": False, "underexposed_fraction": False,
    "edge_width_px": False, "flicker_error": False, "dr_captured_db": True, "data_rate_mb_per_s": False,
    "latency_s": False, "time_resolution_s": False, "targets_seen": True,
    # tracking of the scene's objects (``tracking=True``, scenes with object truth; measure.vision_comparison)
    "tracking_hota": True, "tracking_mota": True, "tracking_idf1": True, "tracking_id_switches": False,
    "tracking_latency_s": False, "tracking_objects_missed": False,
}
#: Default objective: the best point per sensor is the one closest to the truth.
DEFAULT_OBJECTIVE = "psnr_log_db"
#: The name before ``:`` in a varied parameter that makes it a parameter of the scene.
SCENE = "scene"
#: Most values one parameter's spec may give.
MAX_VALUES = 10_000

_OPS = {">=": lambda v, b: v >= b, "<=": lambda v, b: v <= b}


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


def parse_values(option: str, param: Parameter, spec: str) -> list:
    """The values of one ``PARAM=SPEC`` (see the module notes); errors begin with ``option``."""
    spec = spec.strip()
    if not spec:
        raise ViformError(f"{option} gives no values: write PARAM=a,b,c, PARAM=start:stop:step or "
                          "PARAM=log:start:stop:n")
    if param.kind == "bool":
        values = [_bool(option, v) for v in spec.split(",") if v.strip()]
    elif param.kind in ("choice", "text"):
        values = [v.strip() for v in spec.split(",") if v.strip()]
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
        if n > MAX_VALUES:
            raise ViformError(f"{option}: {spec!r} gives {n} points; at most {MAX_VALUES:,} per parameter")
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
        if n > MAX_VALUES:
            raise ViformError(f"{option}: {spec!r} gives {n} points; at most {MAX_VALUES:,} per parameter")
        values = [start + i * step for i in range(n)]
        values = [int(v) for v in values] if param.kind == "int" else [float(f"{v:.12g}") for v in values]
    else:
        values = [_number(option, v.strip(), param.kind) for v in spec.split(",") if v.strip()]
    if not values:
        raise ViformError(f"{option}: {spec!r} gives no points")
    try:
        values = [param.check(v) for v in values]
    except ViformError as exc:
        raise ViformError(f"{option}: {exc}") from None
    return list(dict.fromkeys(values))


def parse_vary(texts, sensors, scene_space: dict | None = None, name: str = "vary_texts") -> dict[str, dict[str, list]]:
    """``[SENSOR:]PARAM=SPEC`` texts → {sensor: {param: values}}; ``scene:PARAM=SPEC`` → {"scene": {…}}.

    Without ``SENSOR:`` the parameter applies to every sensor of the sweep that has it.
    ``scene_space`` holds the scene's parameters (:func:`~viform.measure.sweep.parameters.scene_parameters`);
    errors begin with ``name`` and the text.
    """
    sensors = list(sensors)
    out: dict[str, dict[str, list]] = {k: {} for k in sensors}
    spaces = {k: sweep_parameters(k) for k in sensors}
    for text in texts or ():
        m = re.fullmatch(r"\s*(?:([\w.-]+):)?([A-Za-z_]\w*)\s*=(.*)", text)
        if m is None:
            raise ViformError(f"{name} {text!r}: write [SENSOR:]PARAM=SPEC, e.g. exposure_s=log:1e-4:1e-2:5")
        who, param, spec = m.group(1), m.group(2), m.group(3)
        option = f"{name} {text.strip()}"
        if who == SCENE:
            space = scene_space or {}
            if param not in space:
                raise ViformError(f"{option}: {param!r} is not a numeric parameter of the scene; allowed: "
                                  f"{', '.join(sorted(space)) or 'none (the scene has no parameters)'}")
            grid = out.setdefault(SCENE, {})
            if param in grid:
                raise ViformError(f"{option}: the scene's {param!r} is already varied by another text")
            grid[param] = parse_values(option, space[param], spec)
            continue
        if who is not None and who not in sensors:
            raise ViformError(f"{option}: sensor {who!r} is not in this sweep (its sensors: "
                              f"{', '.join(sensors)}; scene:PARAM varies the scene)")
        targets = [who] if who else [k for k in sensors if param in spaces[k]]
        if not targets:
            allowed = sorted(set().union(*(spaces[k] for k in sensors)))
            raise ViformError(f"{option}: {param!r} is not a parameter of {', '.join(sensors)}; allowed: "
                              f"{', '.join(allowed)} (scene:PARAM varies the scene)")
        for k in targets:
            if param not in spaces[k]:
                raise ViformError(f"{option}: {param!r} is not a parameter of sensor {k!r}; allowed: "
                                  f"{', '.join(sorted(spaces[k]))}")
            if param in out[k]:
                raise ViformError(f"{option}: {param!r} of sensor {k!r} is already varied by another text")
            out[k][param] = parse_values(option, spaces[k][param], spec)
    return out


@dataclass(frozen=True)
class Demand:
    """One demand: ``metric op bound``."""

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


def parse_require(text: str | None, name: str = "require") -> list[Demand]:
    """``"dr_captured_db>=120,edge_width_px<=2"`` → demands (metric names of :data:`METRIC_DIRECTIONS`);
    errors begin with ``name``."""
    if text is None:
        return []
    demands = []
    parts = [p.strip() for p in text.split(",")]
    if not any(parts):
        raise ViformError(f"{name} is empty: give demands such as dr_captured_db>=120,edge_width_px<=2")
    for part in parts:
        if not part:
            raise ViformError(f"{name} {text!r}: an empty demand between commas")
        m = re.fullmatch(r"([A-Za-z_]\w*)\s*(>=|<=)\s*(\S+)", part)
        if m is None:
            raise ViformError(f"{name}: {part!r} is not a demand: write METRIC>=NUMBER or METRIC<=NUMBER, "
                              "e.g. dr_captured_db>=120")
        metric, op, bound = m.groups()
        if metric not in METRIC_DIRECTIONS:
            raise ViformError(f"{name}: {metric!r} is not a metric; allowed: {', '.join(METRIC_DIRECTIONS)}")
        try:
            value = float(bound)
        except ValueError:
            raise ViformError(f"{name}: the bound of {part!r} is not a number") from None
        if not math.isfinite(value):
            raise ViformError(f"{name}: the bound of {part!r} is not a finite number")
        demands.append(Demand(metric, op, value))
    return demands


def check_objective(objective: str, name: str = "objective") -> str:
    """``objective`` when it is a metric of :data:`METRIC_DIRECTIONS`; the error begins with ``name``."""
    if objective not in METRIC_DIRECTIONS:
        raise ViformError(f"{name}: {objective!r} is not a metric; allowed: {', '.join(METRIC_DIRECTIONS)}")
    return objective
