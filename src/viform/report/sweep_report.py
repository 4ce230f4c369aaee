"""``viform sweep``: the design-exploration report (one self-contained HTML file) and the command's runner.

Sections: the designer's answer (which setting meets every ``--require`` demand, else the nearest
miss and by how much); the trade-off of two metrics per figure with every sensor's points, its
default setting marked and the Pareto front; per sensor, each metric over the swept parameter;
the image of the best point per sensor beside the truth (compare's log-lux colour map); every
point's metrics. Figures are inline PNG (no script, no network). The points and metrics come
from :mod:`viform.measure.sweep`.
"""

from __future__ import annotations

import html
import math
import time
from pathlib import Path

import numpy as np

from viform._io import atomic_open, save_figure
from viform._validate import size_text
from viform.measure import comparison as cmp
from viform.measure import sweep as sw
from viform.measure.sweep.run import join_closing
from viform.report.compare_report import (
    _CSS,
    LUX_CMAP,
    UNDER_COLOUR,
    _fmt,
    _image_grid,
    _img,
    _panel_title,
    _shown,
    _suptitle,
    _unit,
)

#: Units of parameter names, by suffix (the project names quantities with their unit).
PARAMETER_UNITS = (("_electrons", "e⁻"), ("_e_per_s", "e⁻/s"), ("_hz", "Hz"), ("_s", "s"), ("_f", "F"),
                   ("_m", "m"), ("_v", "V"), ("_k", "K"), ("_dn", "DN"), ("_fraction", "fraction"))


def parameter_label(name: str) -> str:
    """A parameter's axis label with its unit (``exposure_s`` → "exposure (s)"; a varied scene parameter
    ``scene.brightness`` → "scene brightness")."""
    if name.startswith(sw.SCENE_PREFIX):
        return "scene " + parameter_label(name[len(sw.SCENE_PREFIX):])
    for suffix, unit in PARAMETER_UNITS:
        if name.endswith(suffix):
            stem = name[: -len(suffix)] if unit != "fraction" else name
            return f"{stem.replace('_', ' ')} ({unit})"
    return name.replace("_", " ")


#: Labels of the metrics a sweep adds to compare's.
EXTRA_LABELS = {"targets_seen": f"targets seen (contrast-to-noise ≥ {sw.SEEN_CNR:g})",
                "tracking_hota": "tracking HOTA", "tracking_mota": "tracking MOTA", "tracking_idf1": "tracking IDF1",
                "tracking_id_switches": "tracking ID switches", "tracking_latency_s": "tracking latency (s)",
                "tracking_objects_missed": "objects never tracked"}


def metric_label(key: str) -> str:
    name = cmp.METRICS[key][0] if key in cmp.METRICS else EXTRA_LABELS.get(key, key.replace("_", " "))
    unit = _unit(key) if key in cmp.METRICS else ""
    return f"{name} ({unit})" if unit else name


def _value(r, key) -> float:
    v = _shown(key, r["metrics"].get(key)) if key in cmp.METRICS else r["metrics"].get(key)
    return float(v) if isinstance(v, (int, float)) and v is not None and math.isfinite(v) else math.nan


def _colours(sensors) -> dict:
    import matplotlib.pyplot as plt

    tab = plt.get_cmap("tab10").colors
    return {k: tab[i % len(tab)] for i, k in enumerate(sensors)}


def pareto_front(xs, ys, x_higher: bool, y_higher: bool) -> np.ndarray:
    """Indices of the points no other point beats on both metrics (ties kept), sorted by x."""
    x = np.asarray(xs, float) * (1 if x_higher else -1)
    y = np.asarray(ys, float) * (1 if y_higher else -1)
    keep = []
    for i in range(x.size):
        dominated = np.any((x >= x[i]) & (y >= y[i]) & ((x > x[i]) | (y > y[i])))
        if not dominated:
            keep.append(i)
    keep = np.array(keep, dtype=int)
    return keep[np.argsort(np.asarray(xs, float)[keep])] if keep.size else keep


# ------------------------------------------------------------------ figures
def figure_pareto(doc, pairs):
    """Every point on two metrics per panel (``pairs`` of (x, y) metric keys), one colour per sensor,
    defaults as stars, points meeting the demands ringed in green, the Pareto front of all points as a
    grey line, the demands' bounds as dotted green lines."""
    import matplotlib.pyplot as plt

    records = [r for r in doc["records"] if not r.get("skipped")]
    colours = _colours(doc["sensors"])
    meeting = set(doc["answer"]["meeting"])
    fig, axes = plt.subplots(1, len(pairs), figsize=(6.2 * len(pairs) + 2.6, 5.0), squeeze=False)
    fig.subplots_adjust(left=0.06, right=1 - 2.7 / (6.2 * len(pairs) + 2.6), bottom=0.13, top=0.86, wspace=0.28)
    for ax, (x_key, y_key) in zip(axes.flat, pairs, strict=True):
        _pareto_panel(ax, doc, records, colours, meeting, x_key, y_key)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="center right", bbox_to_anchor=(0.995, 0.5))
    fig.suptitle("Trade-offs: each dot is one setting of one sensor", fontsize=11)
    return fig


def _pareto_panel(ax, doc, records, colours, meeting, x_key, y_key):
    xs = np.array([_value(r, x_key) for r in records])
    ys = np.array([_value(r, y_key) for r in records])
    ok = np.isfinite(xs) & np.isfinite(ys)
    logx = ok.any() and np.all(xs[ok] > 0) and xs[ok].max() / max(xs[ok].min(), 1e-300) > 30
    for key in doc["sensors"]:
        idx = [i for i, r in enumerate(records) if r["sensor"] == key and ok[i]]
        ax.scatter(xs[idx], ys[idx], s=28, color=colours[key], alpha=0.85, label=key, zorder=3)
        for i in idx:
            if records[i]["default"]:
                ax.scatter([xs[i]], [ys[i]], marker="*", s=230, color=colours[key], edgecolor="black",
                           linewidth=0.8, zorder=4)
    ring = [i for i, r in enumerate(records) if r["point_id"] in meeting and ok[i]]
    ax.scatter(xs[ring], ys[ring], s=110, facecolor="none", edgecolor="green", linewidth=1.6, zorder=5,
               label="meets every demand")
    ax.scatter([], [], marker="*", s=150, color="white", edgecolor="black", label="sensor's default setting")
    if ok.sum() >= 2:
        hx, hy = sw.METRIC_DIRECTIONS.get(x_key, True), sw.METRIC_DIRECTIONS.get(y_key, True)
        front = pareto_front(xs[ok], ys[ok], hx, hy)
        # the front's points are outlined, so a front of one point (or of two close ones) is still seen
        ax.plot(xs[ok][front], ys[ok][front], color="0.35", lw=1.2, ls="--", zorder=2)
        ax.scatter(xs[ok][front], ys[ok][front], marker="s", s=95, facecolor="none", edgecolor="0.25",
                   linewidth=1.2, zorder=4, label="Pareto front: no point beats these\non both metrics "
                                                  "(grey squares, dashed line)")
    for d in doc["answer"]["demands"]:
        metric, op, bound = _split_demand(d)
        if metric == x_key:
            ax.axvline(float(_shown(x_key, bound)), color="green", lw=1, ls=":")
        if metric == y_key:
            ax.axhline(float(_shown(y_key, bound)), color="green", lw=1, ls=":")
    if doc["answer"]["demands"]:
        ax.plot([], [], color="green", lw=1, ls=":", label="a demand's bound (--require)")
    if logx:
        ax.set_xscale("log")
    ax.set_xlabel(metric_label(x_key) + (", log scale" if logx else ""))
    ax.set_ylabel(metric_label(y_key))
    better = lambda k: "higher" if sw.METRIC_DIRECTIONS.get(k, True) else "lower"  # noqa: E731
    missing = int((~ok).sum())
    ax.set_title(f"{better(y_key)} {cmp.METRICS.get(y_key, (y_key,))[0]} and {better(x_key)} "
                 f"{cmp.METRICS.get(x_key, (x_key,))[0]} are better\n({missing} point{'s' if missing != 1 else ''} "
                 "without both metrics not shown)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)


def _split_demand(text: str):
    for op in (">=", "<="):
        if op in text:
            m, b = text.split(op)
            return m, op, float(b)
    return text, "", math.nan


def _axes_of(doc, key):
    """(x parameter, [other swept parameters]) of a sensor's curves: x is the one with most values (the
    varied scene parameters count as the sensor's)."""
    grid = {**doc["vary"].get(key, {}),
            **{sw.SCENE_PREFIX + n: v for n, v in (doc["vary"].get(sw.SCENE) or {}).items()}}
    if not grid:
        return None, []
    # most values; on a tie the sensor's own parameter (the designer's knob) before the scene's
    x = max(sorted(grid), key=lambda n: (len(grid[n]), not n.startswith(sw.SCENE_PREFIX)))
    return x, [n for n in sorted(grid) if n != x]


def figure_curves(doc, key: str):
    """Each metric of sensor ``key`` over its swept parameter (one line per value of the others)."""
    import matplotlib.pyplot as plt

    x_name, others = _axes_of(doc, key)
    records = [r for r in doc["records"] if r["sensor"] == key and not r.get("skipped")]
    if x_name is None or not records:
        return None
    metrics = [k for k in sw.metric_columns(records) if k in sw.METRIC_DIRECTIONS
               and any(math.isfinite(_value(r, k)) for r in records)]
    cols = 4
    rows = math.ceil(len(metrics) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(13, 2.55 * rows + 0.9), squeeze=False)
    fig.subplots_adjust(left=0.06, right=0.985, bottom=0.1 if rows == 1 else 0.07, top=1 - 0.75 / (2.55 * rows + 0.9),
                        wspace=0.38, hspace=0.62)
    xs_raw = [r["swept"].get(x_name) for r in records if r["swept"].get(x_name) is not None]
    xs_all = np.array([float(r["swept"].get(x_name, math.nan)) for r in records])
    logx = np.all(xs_all[np.isfinite(xs_all)] > 0) and np.nanmax(xs_all) / np.nanmin(xs_all) > 30
    meeting = set(doc["answer"]["meeting"])
    groups = {}
    for r in records:
        if r["default"] and any(n not in dict(r["settings"]) and r["swept"].get(n) is None for n in [x_name]):
            continue
        groups.setdefault(tuple(r["swept"].get(n) for n in others), []).append(r)
    cmap = plt.get_cmap("viridis")
    for ax, metric in zip(axes.flat, metrics, strict=False):
        for gi, (combo, rs) in enumerate(sorted(groups.items(), key=lambda kv: _order(kv[0]))):
            rs = sorted(rs, key=lambda r: r["swept"][x_name])
            colour = cmap(gi / max(1, len(groups) - 1)) if len(groups) > 1 else "C0"
            label = ", ".join(f"{parameter_label(n)} = {_fmt_param(v)}" for n, v in zip(others, combo, strict=True))
            ax.plot([r["swept"][x_name] for r in rs], [_value(r, metric) for r in rs], "o-", ms=3, lw=1.2,
                    color=colour, label=label or None)
            ring = [r for r in rs if r["point_id"] in meeting]
            if ring:
                ax.scatter([r["swept"][x_name] for r in ring], [_value(r, metric) for r in ring], s=60,
                           facecolor="none", edgecolor="green", linewidth=1.4, zorder=5)
        defaults = [r for r in records if r["default"] and r["swept"].get(x_name) is not None]  # one per scene setting
        if defaults:
            ax.scatter([r["swept"][x_name] for r in defaults], [_value(r, metric) for r in defaults], marker="*",
                       s=150, color="gold", edgecolor="black", linewidth=0.7, zorder=6)
        if logx:
            ax.set_xscale("log")
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in xs_raw):
            from matplotlib.ticker import MaxNLocator

            ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # a count (threshold level): no 2.5
        values = [_value(r, metric) for r in records]
        flat = _floor_span(ax, values)
        ax.set_title(metric_label(metric) + (f"\n{_flat_text(values, flat)}" if flat is not None else ""),
                     fontsize=9)
        ax.set_xlabel(parameter_label(x_name), fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", alpha=0.3)
    for ax in list(axes.flat)[len(metrics):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    extra = ""
    if handles:
        fig.legend(handles, labels, fontsize=8, loc="lower right", ncol=min(4, len(labels)), frameon=False)
        extra = " (one line per value of the other swept parameter)"
    fig.suptitle(f"{key}: each metric over {parameter_label(x_name)}{extra}; gold star = the default setting, "
                 "green ring = meets every demand", fontsize=10)
    return fig


#: The smallest y-span a metric's panel shows, as a fraction of the metric's size: a metric that varies
#: less than this over the sweep is drawn flat, not stretched until rounding noise looks like structure.
MIN_SPAN_FRACTION = 0.05


def _order(combo) -> tuple:
    """Sort key of a line's values: numbers by value (1, 6, 12 — not "1", "12", "6"), None last."""
    return tuple((v is None, v if isinstance(v, (int, float)) else 0, str(v)) for v in combo)


def _floor_span(ax, values) -> float | None:
    """Widen a panel whose values vary by less than :data:`MIN_SPAN_FRACTION` of their size (or by less
    than 1 display unit around 0); returns the half-range of the values when it did, else None."""
    v = np.asarray([x for x in values if math.isfinite(x)], float)
    if v.size == 0:
        return None
    lo, hi = float(v.min()), float(v.max())
    centre = (lo + hi) / 2
    floor = MIN_SPAN_FRACTION * abs(centre) if centre != 0 else 1.0
    if hi - lo >= floor:
        return None
    ax.set_ylim(centre - floor / 2, centre + floor / 2)
    return (hi - lo) / 2


def _flat_text(values, half_range: float) -> str:
    """A panel's note when its values barely vary: the same value everywhere, or the half-range."""
    v = [x for x in values if math.isfinite(x)]
    if half_range == 0:
        return f"the same at every point: {v[0]:.4g}"
    return f"flat: every point within ±{half_range:.2g} of {(min(v) + max(v)) / 2:.4g}"


def _fmt_param(v) -> str:
    if isinstance(v, float) and v >= 1000:
        return f"{v / 1e3:g} k"
    return _fmt(v)


def figure_best(doc, scene, out: Path, scenes=None):
    """The truth and the best point of each sensor at the middle instant, one log-lux colour map; where
    scene parameters are varied, a truth per scene setting (``scenes(settings)`` makes it) and its bests."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    instants = doc["context"]["instants_s"]
    i = len(instants) // 2
    t = instants[i]
    # one truth per varied scene setting (each answered apart), made by ``scenes(settings)``
    groups = list(dict.fromkeys(tuple(sorted((v.get("scene") or {}).items()))
                                for v in doc["answer"]["per_sensor"].values())) or [()]
    truths = {g: (scene if not g or scenes is None else scenes(g)) for g in groups}
    demands = [sc.demand() for sc in truths.values() if hasattr(sc, "demand")]
    lows = [d["min_lux"] for d in demands] or [max(float(sc.illuminance_lux(t).min()), 1e-4) for sc in truths.values()]
    highs = [d["max_lux"] for d in demands] or [float(sc.illuminance_lux(t).max()) for sc in truths.values()]
    norm = LogNorm(vmin=min(lows), vmax=max(highs))
    panels = []
    by_id = {r["point_id"]: r for r in doc["records"]}
    for g in groups:
        where = f"at {t * 1e3:.2f} ms" + (f"\n{sw.scene_text(dict(g))}" if g else "")
        panels.append((_panel_title("truth", where), truths[g].illuminance_lux(t)))
        for key, v in doc["answer"]["per_sensor"].items():
            if tuple(sorted((v.get("scene") or {}).items())) != g:
                continue
            images = sw.load_images(out, v["best"])
            if images is None or v.get("sensor", key) == "gated":
                continue
            what = "best meeting the demands" if v["meets"] else ("nearest miss" if doc["answer"]["demands"]
                                                                  else f"best by {doc['answer']['objective']}")
            panels.append((_panel_title(f"{by_id[v['best']]['label']}", what), images[i].astype(np.float64)))
    titles = [p[0] for p in panels]
    fig, axes, cax = _image_grid(len(panels), scene.shape, max(tt.count("\n") + 1 for tt in titles))
    cmap = plt.get_cmap(LUX_CMAP).with_extremes(bad=UNDER_COLOUR)
    im = None
    for ax, (title, lux) in zip(axes.flat, panels, strict=False):
        im = ax.imshow(np.ma.masked_invalid(np.maximum(lux, norm.vmin)), cmap=cmap, norm=norm,
                       interpolation="nearest")
        ax.set_title(title, fontsize=8)
    fig.colorbar(im, cax=cax, extend="both", label="illuminance on the sensor\n(lux, log scale)")
    _suptitle(fig, f"Best setting of each sensor at t = {t * 1e3:.2f} ms beside the truth (same colour map; "
              "grey = under-exposed, no measurement)")
    return fig


# ------------------------------------------------------------------ HTML
def write_sweep_report(doc, scene, out, command: str = "", started_s: float | None = None,
                       demand_notes: list[str] | None = None, scenes=None) -> Path:
    """Write ``out/report.html`` (figures under ``out/figures``); returns its path.

    ``demand_notes`` say where the demands come from (printed under them); ``scenes(settings)`` makes
    the scene at varied scene settings (for their truths)."""
    out = Path(out)
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    paths = {}
    if any(not r.get("skipped") for r in doc["records"]):
        save_figure(figs / "pareto.png", figure_pareto(doc, doc["pareto"]))
        paths["pareto"] = (figs / "pareto.png", "trade-offs of two metrics, every point")
    for key in doc["sensors"]:
        fig = figure_curves(doc, key)
        if fig is not None:
            save_figure(figs / f"curves_{key}.png", fig)
            paths[f"curves_{key}"] = (figs / f"curves_{key}.png", f"metrics of {key} over its settings")
    if any(not r.get("skipped") for r in doc["records"]):
        save_figure(figs / "best.png", figure_best(doc, scene, out, scenes))
        paths["best"] = (figs / "best.png", "best setting of each sensor beside the truth")
    e = html.escape
    ctx = doc["context"]
    ans = doc["answer"]
    run_time = time.perf_counter() - started_s if started_s is not None else None
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>viform sweep: {e(ctx['scene'])}"
             f"</title><style>{_CSS}</style></head><body>",
             f"<h1>Design sweep on '{e(ctx['scene'])}': which setting meets the scene's demands?</h1>",
             f"<p class='note'>{size_text(ctx['height'], ctx['width'], 'pixels')}, "
             f"{ctx['duration_s'] * 1e3:g} ms clip, images "
             f"scored at {', '.join(f'{t * 1e3:.2f} ms' for t in ctx['instants_s'])} against the scene's truth "
             f"with the metrics of <code>viform compare</code>. {doc['n_points']} points "
             f"({doc['computed']} computed now, {doc['reused']} reused from earlier runs) on "
             f"{doc['workers'] or 'no'} dask worker{'s' if doc['workers'] != 1 else ''}"
             + (f" ({doc['computed_here']} of them in the command's own process while the workers started)"
                if doc["workers"] and doc.get("computed_here") else "") + "; the points took "
             f"{doc['seconds']:.1f} s ({doc['cpu_seconds']:.1f} CPU-seconds computed now)"
             + (f", the whole command {run_time:.1f} s" if run_time else "") + "."
             + (f" Command: <code>{e(command)}</code>." if command else "") + "</p>"]
    parts.append("<section id='answer'><h2>The answer</h2><ul class='verdict'>")
    parts += [f"<li>{e(line)}</li>" for line in ans["sentences"]]
    demands = ", ".join(ans["demands"]) or "none (give --require)"
    parts.append(f"</ul><p class='note'>Demands: {e(demands)}. Best = highest/lowest "
                 f"{e(metric_label(ans['objective']))} among the points that meet every demand; nearest miss = "
                 "the point missing the fewest demands, then by the smallest relative shortfall. A metric not "
                 "defined for a sensor (n/a) counts as missed.</p>")
    if demand_notes:
        parts.append("<p class='note'>Where the demands come from:</p><ul class='note'>"
                     + "".join(f"<li>{e(n)}</li>" for n in demand_notes) + "</ul>")
    parts.append("<table><tr><th>sensor</th><th>meets every demand</th><th>setting</th>"
                 f"<th>{e(metric_label(ans['objective']))}</th><th>points meeting / swept</th><th>misses</th></tr>")
    for key, v in ans["per_sensor"].items():
        misses = "; ".join(sw._miss_text(m) for m in v.get("misses", [])) or "—"
        meets = "— (no demands)" if v["meets"] is None else ("yes" if v["meets"] else "no")
        counted = f"— / {v['n_points']}" if v["meets"] is None else f"{v['n_meeting']} / {v['n_points']}"
        parts.append(f"<tr data-sensor='{e(key)}'><td>{e(key)}</td><td>{meets}</td>"
                     f"<td>{e(sw._settings_text(v))}</td><td>{_fmt(_shown(ans['objective'], v['objective']))}</td>"
                     f"<td>{counted}</td><td>{e(misses)}</td></tr>")
    parts.append("</table></section>")
    parts.append("<section id='pareto'><h2>Trade-offs</h2><p class='note'>Each dot is one setting of one sensor; "
                 "the star is the sensor's default setting (what <code>viform compare</code> uses); green rings "
                 "meet every demand; dotted green lines are the demands' bounds.</p>")
    parts += [_img(*paths[k]) for k in paths if k == "pareto"]
    parts.append("</section><section id='curves'><h2>Each metric over the swept settings</h2>")
    parts += [_img(*paths[k]) for k in paths if k.startswith("curves_")]
    if not any(k.startswith("curves_") for k in paths):
        parts.append("<p>No parameter was varied (give --vary).</p>")
    parts.append("</section>")
    if "best" in paths:
        parts.append("<section id='best'><h2>The best setting of each sensor, beside the truth</h2>"
                     + _img(*paths["best"]) + "</section>")
    cols = sw.metric_columns(doc["records"])
    cols = [c for c in cols if c in cmp.METRICS or c in EXTRA_LABELS]
    params = sorted({n for r in doc["records"] for n in r["swept"]})
    parts.append("<section id='points'><h2>Every point</h2><table><tr><th>point</th>"
                 + "".join(f"<th>{e(parameter_label(p))}</th>" for p in params)
                 + "".join(f"<th>{e(metric_label(c))}</th>" for c in cols)
                 + "</tr>")
    meeting = set(ans["meeting"])
    for r in doc["records"]:
        mark = " ✓" if r["point_id"] in meeting else ""
        parts.append(f"<tr data-point='{e(r['point_id'])}' data-sensor='{e(r['sensor'])}'><td>{e(r['label'])}{mark}"
                     "</td>" + "".join(f"<td>{_fmt(r['swept'].get(p))}</td>" for p in params))
        if r.get("skipped"):
            parts.append(f"<td colspan='{len(cols)}'>not applicable: {e(r['skipped'])}</td></tr>")
            continue
        parts += [f"<td data-metric='{c}'>{_fmt(_shown(c, r['metrics'].get(c)))}</td>" for c in cols]
        parts.append("</tr>")
    parts.append("</table><p class='note'>✓ meets every demand. Units as in the compare report: saturated and "
                 "under-exposed in %, latency and integration time in ms. The same rows are in sweep.zarr "
                 "(SI units) and sweep.json.</p></section>")
    parts.append("<p class='note'>Made by viform sweep; self-contained (no network).</p></body></html>")
    with atomic_open(out / "report.html", "w") as f:
        f.write("".join(parts))
    return out / "report.html"


def console_lines(doc) -> list[str]:
    """The console summary: per sensor the best (or nearest) setting, then the answer."""
    ans = doc["answer"]
    here = doc.get("computed_here", 0)
    where = (f"{doc['workers']} dask workers" + (f" ({here} of the points in this process while they started)"
                                                  if here else "")) if doc["workers"] else "no dask workers"
    lines = [f"{doc['n_points']} points ({doc['computed']} computed, {doc['reused']} reused) in "
             f"{doc['seconds']:.1f} s on {where}, {doc['cpu_seconds']:.1f} CPU-s"]
    width = max([len(k) for k in ans["per_sensor"]] + [6])
    for key, v in ans["per_sensor"].items():
        if v["meets"] is None:  # no demands: nothing "meets"; the best by the objective
            lines.append(f"  {key:<{width}}  best    {sw._settings_text(v)}  "
                         f"({ans['objective']} {_fmt(v['objective'])}; of {v['n_points']} points, no demands)")
            continue
        lines.append(f"  {key:<{width}}  {'meets ' if v['meets'] else 'misses'}  {sw._settings_text(v)}  "
                     f"({ans['objective']} {_fmt(v['objective'])}; {v['n_meeting']}/{v['n_points']} meet)")
    lines += [f"- {s}" for s in ans["sentences"]]
    return lines


def run_sweep_report(plan, out, *, workers=None, scheduler=None, client=None, memory_limit="auto",
                     progress: bool = True, command: str = "", started_s: float | None = None,
                     crash_after_points: int | None = None, demand_notes: list[str] | None = None,
                     device: str = "cpu", **run_options) -> dict:
    """Run a planned sweep into ``out`` and write its report; returns the sweep document.

    ``run_options`` go to :func:`viform.measure.sweep.sweep` (e.g. ``connect_timeout_s``). A local
    cluster of the sweep's own is closed while the report is written (its workers' shut-down is waiting)."""
    started = time.perf_counter() if started_s is None else started_s
    closing: list = []
    failed = True
    try:
        doc = sw.sweep(plan, out, workers=workers, scheduler=scheduler, client=client, memory_limit=memory_limit,
                       progress=progress, crash_after_points=crash_after_points, device=device,
                       close_later=closing, **run_options)
        write_sweep_report(doc, plan.context.make_scene(), out, command, started, demand_notes,
                           scenes=plan.context.make_scene)
        failed = False
    finally:
        join_closing(closing, failed)
    doc["report"] = str(Path(out) / "report.html")
    return doc
