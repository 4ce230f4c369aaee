"""The designer's answer: which points meet every demand, the best per sensor, else the nearest miss.

A point *meets* only demands: with none given, the answer names each sensor's best point by the
objective and says that nothing was demanded. Where the scene's parameters are varied too, each
scene setting gets its own answer (a designer chooses the sensor's setting, not the scene's).
"""

from __future__ import annotations

import math

from viform.measure import comparison as cmp
from viform.measure.sweep.plan import _fmt_value
from viform.measure.sweep.specs import DEFAULT_OBJECTIVE, METRIC_DIRECTIONS


def _scene_key(r) -> tuple:
    return tuple(sorted((r.get("scene") or {}).items()))


def scene_text(scene: dict) -> str:
    """``{"brightness": 0.1}`` → "scene brightness = 0.1" (empty for no scene setting)."""
    return ", ".join(f"scene {n} = {_fmt_value(v)}" for n, v in scene.items())


def answer(records, demands, objective: str = DEFAULT_OBJECTIVE) -> dict:
    """Which points meet every demand; the best per sensor by ``objective``; else the nearest miss.

    The nearest miss of a sensor is its point that misses the fewest demands, then by the smallest
    sum of relative shortfalls (shortfall / |bound|); a metric not defined for a point misses.
    Without demands no point "meets" anything (``meets`` is None): each sensor's best point by
    ``objective`` is named. Records with scene settings (``record["scene"]``) are answered per
    scene setting: ``per_sensor`` is then keyed "SENSOR · scene NAME = VALUE". Sensors none of whose
    points could be scored are listed in ``not_scored`` with the reason.
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

    def shown(value):
        return value if math.isfinite(value) else math.nan

    groups = list(dict.fromkeys(_scene_key(r) for r in records))
    sentences = []
    for group in groups:
        scene = dict(group)
        here = {}
        for key in dict.fromkeys(r["sensor"] for r in rows if _scene_key(r) == group):
            mine = [r for r in rows if r["sensor"] == key and _scene_key(r) == group]
            entry = {"sensor": key, "scene": scene, "n_points": len(mine)}
            if not demands:
                best = sorted(mine, key=objective_value, reverse=higher)[0]
                entry.update(meets=None, best=best["point_id"], label=best["label"], settings=best["settings"],
                             objective=shown(objective_value(best)), n_meeting=None)
            else:
                meeting = [r for r in mine if not miss_list(r)]
                if meeting:
                    best = sorted(meeting, key=objective_value, reverse=higher)[0]
                    entry.update(meets=True, best=best["point_id"], label=best["label"], settings=best["settings"],
                                 objective=shown(objective_value(best)), n_meeting=len(meeting))
                else:
                    near = min(mine, key=lambda r: (*rank_miss(r),
                                                    -objective_value(r) if higher else objective_value(r)))
                    entry.update(meets=False, best=near["point_id"], label=near["label"], settings=near["settings"],
                                 objective=shown(objective_value(near)), misses=miss_list(near), n_meeting=0)
            here[key] = entry
        lines = answer_sentences(here, demands, objective)
        if len(groups) > 1:
            lines = [f"At {scene_text(scene)}: {lines[0]}", *lines[1:]]
            here = {f"{k} · {scene_text(scene)}": v for k, v in here.items()}
        per_sensor.update(here)
        sentences += lines
    not_scored = {}
    for r in records:
        if r.get("skipped") and not any(x["sensor"] == r["sensor"] for x in rows):
            not_scored.setdefault(r["sensor"], r["skipped"])
    sentences += [f"{k}: not scored on this scene: {why}." for k, why in not_scored.items()]
    meeting_ids = [r["point_id"] for r in rows if demands and not miss_list(r)]
    return {"demands": [d.text() for d in demands], "objective": objective, "meeting": meeting_ids,
            "per_sensor": per_sensor, "not_scored": not_scored, "sentences": sentences}


def _unit(metric: str) -> str:
    return cmp.METRICS[metric][1] if metric in cmp.METRICS else ""


def _miss_text(m) -> str:
    if not math.isfinite(m["shortfall"]):
        return f"{m['demand']} (not measurable for this sensor here)"
    unit = _unit(m["metric"])
    return (f"{m['demand']} by {m['shortfall']:.3g}{' ' + unit if unit and unit != 'fraction' else ''} "
            f"(it reaches {m['value']:.4g})")


def _objective_text(objective: str, value) -> str:
    if value is None or not math.isfinite(value):
        return f"{objective} is not defined for it here"
    return f"{objective} = {value:.4g}"


def answer_sentences(per_sensor: dict, demands, objective: str) -> list[str]:
    """The designer's answer in words: who meets the demands at which setting, else the nearest miss;
    without demands, each sensor's best setting by ``objective`` (and that nothing was demanded)."""
    if not per_sensor:
        return ["No point of the sweep could be scored on this scene."]
    if not demands:
        return ["No demands were given, so no setting is said to meet them; the best setting of each sensor by "
                f"{objective}:"] + [f"{k}: {_settings_text(v)} ({_objective_text(objective, v['objective'])})."
                                    for k, v in per_sensor.items()]
    lines = []
    meets = {k: v for k, v in per_sensor.items() if v["meets"]}
    wanted = " and ".join(d.text() for d in demands)
    if meets:
        for k, v in meets.items():
            lines.append(f"{k} meets {wanted} at {_settings_text(v)} ({v['n_meeting']} of {v['n_points']} "
                         f"swept settings do; best by {objective}: "
                         + (f"{v['objective']:.4g}" if math.isfinite(v["objective"]) else "n/a") + ").")
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
