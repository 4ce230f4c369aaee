"""The designer's answer: which points meet every demand, the best per sensor, else the nearest miss."""

from __future__ import annotations

import math

from viform.measure import comparison as cmp
from viform.measure.sweep.plan import _fmt_value
from viform.measure.sweep.specs import DEFAULT_OBJECTIVE, METRIC_DIRECTIONS


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
