"""``viform compare``: shoot one scene with every sensor and write report.html + metrics.json.

The report is one self-contained HTML file (figures inline as base64 PNG, no script, no
network). Every image of light uses the same log-lux colour map and one colour bar in
lux; error maps use one diverging scale in decades. Metrics and the text saying which
sensor wins on what come from :mod:`viform.measure.comparison`.
"""

from __future__ import annotations

import base64
import html
import json
import math
import textwrap
import time
from pathlib import Path

import numpy as np

from viform._io import atomic_open, save_figure, write_json
from viform._validate import ViformError, check_int, check_positive, size_text
from viform.measure import comparison as cmp

#: Most bytes of spike clip a comparison holds in memory.
MAX_SPIKE_BYTES = 2e9
#: Colour map of light images (perceptually uniform, dark = little light).
LUX_CMAP = "inferno"
#: Colour of under-exposed pixels (below the noise floor, or no spike): not a measurement.
UNDER_COLOUR = "0.62"
#: Error maps: log10(estimate / truth) in decades, clipped to ± this.
ERROR_SPAN_DECADES = 2.0


def check_sensors(sensors) -> list[str]:
    """Validate a list of comparison sensor names (from ``--sensors``): names of the sensor catalogue."""
    keys = list(sensors) if sensors else list(cmp.DEFAULT_SENSORS)
    if not keys:
        raise ViformError("--sensors is empty: give at least one sensor")
    for k in keys:
        cmp.compare_entry(k, what="--sensors")
    return list(dict.fromkeys(keys))


def default_instants(duration_s: float) -> list[float]:
    """Three instants inside the clip (30 %, 50 %, 70 % of it)."""
    return [float(f"{f * duration_s:.6g}") for f in (0.3, 0.5, 0.7)]


def run_comparison(scene, duration_s: float, sensors=None, instants_s=None, seed: int = 0,
                   progress: bool = True, settings: dict | None = None, on_valid=None) -> dict:
    """Shoot ``scene`` with each sensor and score it; returns shots, metrics and the verdict.

    ``settings`` maps a sensor's name to its parameters' values ({name: {parameter: value}}).
    ``on_valid``: called with no arguments once every input is checked, before the first shot (a command
    announces a first-run compilation there, so a refused input prints its error alone).
    """
    duration_s = check_positive("--duration", duration_s)
    keys = check_sensors(sensors)
    settings = settings or {}
    models = {k: cmp.make_compare_sensor(k, **settings.get(k, {})) for k in keys}  # bad settings: refused now
    for k, model in models.items():  # a spike clip is held in memory (1 byte per pixel-tick) for the reconstructions
        if cmp.compare_entry(k).family != "spike":
            continue
        need = scene.height * scene.width * duration_s * model.parameters.clock_hz
        if need > MAX_SPIKE_BYTES:
            raise ViformError(f"--duration {duration_s:g} s of a {size_text(scene.height, scene.width)} spike clip "
                              f"needs "
                              f"{need / 1e9:.3g} GB in memory, more than the {MAX_SPIKE_BYTES / 1e9:g} GB limit; "
                              "shorten --duration or lower --height/--width")
    if all(k == "gated" for k in keys) and getattr(scene, "active", None) is None:
        raise ViformError(f"--sensors gated: the gated camera needs a scene with range (night-road-fog); "
                          f"scene {scene.name!r} has none")
    instants = list(instants_s) if instants_s is not None else default_instants(duration_s)
    for t in instants:
        if not 0 <= t < duration_s:
            raise ViformError(f"instant {t!r} s is outside the clip [0, {duration_s:g}) s")
    if on_valid is not None:
        on_valid()
    shots, timings = [], {}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(keys), desc="compare", unit="sensor", leave=False)
    try:
        for key in keys:
            if bar is not None:
                bar.set_postfix_str(key)
            started = time.perf_counter()
            for shot in cmp.shoot(key, scene, duration_s, instants, seed=seed, sensor=models[key]):
                shot.metrics = cmp.score(shot, scene, instants)
                shots.append(shot)
            timings[key] = time.perf_counter() - started
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    demand = scene.demand() if hasattr(scene, "demand") else None
    result = {"shots": shots, "instants_s": instants, "demand": demand, "scene": scene,
              "duration_s": duration_s, "verdict": cmp.verdict(shots, demand), "timings_s": timings}
    result["vision"] = _vision(result)
    return result


def _vision(result):
    """The vision section's scores where the scene has object truth (measure.vision_comparison), else None."""
    from viform.measure.vision_comparison import vision_scores

    return vision_scores(result)


# ------------------------------------------------------------------ figures
def _lux_norm(result):
    from matplotlib.colors import LogNorm

    d = result["demand"]
    if d:
        return LogNorm(vmin=d["min_lux"], vmax=d["max_lux"])
    truth = result["scene"].illuminance_lux(result["instants_s"][0])
    return LogNorm(vmin=max(float(truth.min()), 1e-4), vmax=float(truth.max()))


def _panel_grid(n):
    cols = min(4, n)
    return math.ceil(n / cols), cols


#: Characters per line of a panel title (fontsize 8 in a 3.3-inch panel): longer sensor labels
#: are wrapped so no title runs into its neighbour or off the figure's edge.
TITLE_CHARS = 46


def _panel_title(*lines: str) -> str:
    """A panel title whose lines are wrapped to the panel's width."""
    return "\n".join(textwrap.fill(line, TITLE_CHARS) for line in lines)


def _image_grid(n_panels: int, shape, title_lines: int = 2):
    """A grid of image panels with room for titles, a suptitle and one colour bar on the right.

    ``title_lines`` is the most lines any panel title has (see :func:`_panel_title`).
    Laid out by hand (no constrained layout: it costs seconds per figure on a busy machine).
    """
    import matplotlib.pyplot as plt

    rows, cols = _panel_grid(n_panels)
    h, w = shape
    panel_w = 3.3
    title_h = 0.14 * title_lines + 0.17  # fontsize-8 lines and the pad above the image
    panel_h = panel_w * h / w + title_h
    # one row of wide panels is short: keep room for the colour bar's label along its length
    fig_w, fig_h = panel_w * cols + 1.6, max(panel_h * rows + 0.6, 3.4)
    fig, axes = plt.subplots(rows, cols, figsize=(fig_w, fig_h), squeeze=False,
                             gridspec_kw=dict(left=0.01, right=1 - 1.5 / fig_w, bottom=0.02, top=1 - 0.8 / fig_h,
                                              wspace=0.06, hspace=title_h / (panel_h - title_h) + 0.05))
    cax = fig.add_axes([1 - 1.15 / fig_w, 0.08, 0.16 / fig_w, 0.78])
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[n_panels:]:
        ax.axis("off")
    return fig, axes, cax


def _suptitle(fig, text: str) -> None:
    """A figure title wrapped to the figure's width (a grid of two or three panels is narrow)."""
    chars = int(fig.get_figwidth() * 72 / 5.6)  # fontsize 10: about 5.6 pt a character
    fig.suptitle(textwrap.fill(text, chars), fontsize=10)


def _when(est, t):
    a, b = est.source_time_s
    if a == b:
        return f"at {t * 1e3:.2f} ms"
    return f"light of {a * 1e3:.2f}–{b * 1e3:.2f} ms"


def figure_instant(result, index: int):
    """Truth and every sensor's image at one instant, one log-lux colour map and colour bar."""
    import matplotlib.pyplot as plt

    t = result["instants_s"][index]
    scene = result["scene"]
    shots = [s for s in result["shots"] if not s.skipped and s.lux_units]
    norm = _lux_norm(result)
    floor = norm.vmin
    im = None
    cmap = plt.get_cmap(LUX_CMAP).with_extremes(bad=UNDER_COLOUR)
    panels = [("truth", scene.illuminance_lux(t), f"at {t * 1e3:.2f} ms")]
    for s in shots:  # under-exposed pixels in grey: their value is a bound, not a measurement
        est = s.estimates[index]
        panels.append((s.label, np.where(est.underexposed, np.nan, np.maximum(np.nan_to_num(est.lux), floor)),
                       _when(est, t)))
    titles = [_panel_title(title, when) for title, _, when in panels]
    fig, axes, cax = _image_grid(len(panels), scene.shape, max((t.count("\n") + 1 for t in titles), default=2))
    for ax, title, (_, lux, _) in zip(axes.flat, titles, panels, strict=False):
        im = ax.imshow(np.ma.masked_invalid(np.maximum(lux, floor)), cmap=cmap, norm=norm, interpolation="nearest")
        ax.set_title(title, fontsize=8)
    # sensors can read beyond the scene's range: the ends of the bar say that such pixels are clipped
    fig.colorbar(im, cax=cax, extend="both", label="illuminance on the sensor\n(lux, log scale)")
    _suptitle(fig, f"Scene '{scene.name}' at t = {t * 1e3:.2f} ms: truth and each sensor's image (same colour "
              "map; black = at or below the scene's darkest level; grey = under-exposed, no measurement)")
    return fig


def figure_scene(result):
    """The truth at the first instant with its parts named (scenes that name them)."""
    import matplotlib.pyplot as plt

    scene = result["scene"]
    t = result["instants_s"][0]
    h, w = scene.shape
    fig, ax = plt.subplots(figsize=(9.5, 9.5 * h / w * 0.8 + 0.8))
    fig.subplots_adjust(left=0.01, right=0.86, bottom=0.02, top=0.92)
    im = ax.imshow(scene.illuminance_lux(t), cmap=LUX_CMAP, norm=_lux_norm(result), interpolation="nearest")
    box = dict(boxstyle="round,pad=0.2", fc="black", alpha=0.55, lw=0)
    renderer = fig.canvas.get_renderer()
    placed = []  # label boxes drawn so far (moving parts can bring two labels together)
    for name, where in scene.landmarks(t).items():
        x, y = where[:2]
        if len(where) == 4:  # label placed apart, with an arrow to its point
            ax.annotate(name, (x, y), xytext=where[2:], textcoords="data", fontsize=8, color="white", va="center",
                        bbox=box, arrowprops=dict(arrowstyle="->", color="white", lw=0.8))
            continue
        right = x > 0.7 * w  # labels near the right edge extend leftwards, so none is cut off
        note = ax.annotate(name, (x, y), xytext=(0, 0), textcoords="offset points", fontsize=8, color="white",
                           ha="right" if right else "left", va="top", bbox=box)
        _clear_of(note, placed, renderer)
    ax.set_xticks([])
    ax.set_yticks([])
    cax = fig.add_axes([0.88, 0.1, 0.025, 0.78])
    fig.colorbar(im, cax=cax, label="illuminance on the sensor (lux, log scale)")
    ax.set_title(f"The scene '{scene.name}' at t = {t * 1e3:.2f} ms (the truth every sensor is scored against)",
                 fontsize=10)
    return fig


def _clear_of(note, placed: list, renderer, step_pt: float = 11.0, tries: int = 8) -> None:
    """Move a label down, a line at a time, until its box overlaps no label in ``placed``; add it."""
    for _ in range(tries):
        b = note.get_window_extent(renderer)
        if not any(b.x0 < p.x1 and p.x0 < b.x1 and b.y0 < p.y1 and p.y0 < b.y1 for p in placed):
            break
        x, y = note.get_position()  # offset from the point, in points
        note.set_position((x, y - step_pt))
    placed.append(note.get_window_extent(renderer))


def figure_errors(result, index: int):
    """log10(estimate / truth) per sensor at one instant, one diverging scale in decades."""

    t = result["instants_s"][index]
    scene = result["scene"]
    shots = [s for s in result["shots"] if not s.skipped and s.lux_units]
    d = result["demand"] or {"min_lux": 1e-4, "max_lux": 1e6}
    lo, hi = d["min_lux"] / 2, d["max_lux"] * 2
    truth = cmp.log_lux(scene.illuminance_lux(t), lo, hi)
    import matplotlib.pyplot as plt

    titles = [_panel_title(s.label, f"saturated {s.estimates[index].saturated.mean():.0%}, "
                                     f"under-exposed {s.estimates[index].underexposed.mean():.0%}") for s in shots]
    fig, axes, cax = _image_grid(len(shots), scene.shape, max((t.count("\n") + 1 for t in titles), default=2))
    im = None
    # under-exposed pixels hold a bound, not a measurement: grey, as in the image panels
    cmap = plt.get_cmap("RdBu_r").with_extremes(bad=UNDER_COLOUR)
    for ax, s, title in zip(axes.flat, shots, titles, strict=False):
        est = s.estimates[index]
        err = np.where(est.underexposed, np.nan, cmp.log_lux(est.lux, lo, hi) - truth)
        im = ax.imshow(np.ma.masked_invalid(err), cmap=cmap, vmin=-ERROR_SPAN_DECADES, vmax=ERROR_SPAN_DECADES,
                       interpolation="nearest")
        ax.set_title(title, fontsize=8)
    bar = fig.colorbar(im, cax=cax, extend="both")
    bar.set_label("error: log10(estimate / truth), decades\nclipped at ±2\nred = too bright, blue = too dark",
                  fontsize=7)
    _suptitle(fig, f"Error against the truth at t = {t * 1e3:.2f} ms (one scale for every sensor; "
              "grey = under-exposed, no measurement)")
    return fig


def figure_dilemma(result):
    """Temporal resolution against dynamic range captured: one point per sensor, the scene's demand marked."""
    import matplotlib.pyplot as plt

    shots = [s for s in result["shots"] if not s.skipped and s.lux_units]
    fig, ax = plt.subplots(figsize=(11.5, 5.6))
    fig.subplots_adjust(left=0.07, right=0.6, bottom=0.11, top=0.92)
    markers = "osD^v<>phXP"
    colours = plt.get_cmap("tab10").colors
    placed: list[tuple[float, float]] = []
    dotted = False
    for i, s in enumerate(shots):
        x = s.time_resolution_s
        y = s.metrics.get("dr_captured_db", math.nan)
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ax.scatter([x], [y], s=70, marker=markers[i % len(markers)], color=colours[i % len(colours)],
                   label=f"{i + 1}  {s.label}", zorder=3, edgecolor="black", linewidth=0.5)
        # a dotted line on to the frame interval: a short integration repeated seldom still misses motion
        interval = cmp.frame_interval_s(s)
        if math.isfinite(interval) and interval > 1.5 * x:
            ax.plot([x, interval], [y, y], ls=":", lw=1.6, color=colours[i % len(colours)], zorder=2)
            dotted = True
        # the point's number beside it (the legend names it); nudged when another sits close by
        # above it when it is the higher of the two, below when lower, so no marker hides a number
        near = [py for (px, py) in placed if abs(math.log10(px / x)) < 0.2 and abs(py - y) < 5]
        dy = 3 + (10 * len(near) if near and y >= max(near) else -10 * len(near))
        ax.annotate(str(i + 1), (x, y), xytext=(7, dy), textcoords="offset points", fontsize=8,
                    fontweight="bold", color=colours[i % len(colours)], zorder=5)
        placed.append((x, y))
    if dotted:  # one legend entry for every sensor's dotted line
        ax.plot([], [], ls=":", lw=1.6, color="0.3", label="dotted: from the integration time on to the frame "
                                                           "interval (the time between two images)")
    d = result["demand"]
    if d and math.isfinite(d["time_resolution_s"]):
        ax.scatter([d["time_resolution_s"]], [d["dynamic_range_db"]], marker="*", s=320, color="gold",
                   edgecolor="black", zorder=4, label="scene demand (1 px of motion; its full range)")
        ax.axvline(d["time_resolution_s"], color="0.5", ls="--", lw=1)
        ax.axhline(d["dynamic_range_db"], color="0.5", ls="--", lw=1)
        ax.fill_between([1e-7, d["time_resolution_s"]], d["dynamic_range_db"], d["dynamic_range_db"] + 40,
                        color="gold", alpha=0.15, zorder=0, label="region meeting both demands")
    ax.set_xscale("log")
    xs = [s.time_resolution_s for s in shots if math.isfinite(s.time_resolution_s)]
    xs += [cmp.frame_interval_s(s) for s in shots if math.isfinite(cmp.frame_interval_s(s))]
    if d and math.isfinite(d["time_resolution_s"]):
        xs.append(d["time_resolution_s"])
    if xs:
        ax.set_xlim(min(xs) / 3, max(xs) * 4)
    ys = [s.metrics.get("dr_captured_db", 0) for s in shots] + ([d["dynamic_range_db"]] if d else [])
    ax.set_ylim(0, max(ys) * 1.15 + 5)
    ax.set_xlabel("integration time per image (s, log scale): shorter = sharper motion")
    ax.set_ylabel("scene dynamic range captured (dB)")
    ax.set_title("The dilemma: time resolution against dynamic range (top left is better)")
    ax.grid(True, which="both", alpha=0.3)
    _legend_at_right(fig, ax)
    return fig


def _wrap_label(label: str, chars: int) -> str:
    """A legend label on lines of at most ``chars``; a long sensor label breaks at its " · " (the imaging
    method goes on its own line), so no line ends in a dangling separator that reads as a cut."""
    if len(label) <= chars:
        return label
    head, *parts = label.split(" · ")
    lines = textwrap.wrap(head, chars, subsequent_indent="      ")
    for part in parts:
        lines += textwrap.wrap("· " + part, chars, initial_indent="      ", subsequent_indent="        ")
    return "\n".join(lines)


def _legend_at_right(fig, ax, chars: int = 44) -> None:
    """The axes' legend on the figure's right, labels wrapped; the axes shrink so it fits.

    Sensor labels are long (preset, Q, clock, method): the legend's drawn size is measured and
    the axes end where it begins, so no label is cut off at the figure's edge.
    """
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    wrapped = [_wrap_label(lb, chars) for lb in labels]
    leg = fig.legend(handles, wrapped, fontsize=8, loc="center right", bbox_to_anchor=(0.995, 0.5))
    box = leg.get_window_extent(fig.canvas.get_renderer())
    if box.height > 0.98 * fig.bbox.height:  # many sensors: a taller figure, same legend
        fig.set_figheight(box.height / fig.dpi / 0.95)
    fig.subplots_adjust(right=0.985 - box.width / fig.bbox.width - 0.02)


def figure_gated(result):
    """The gated camera's frame (laser returns, electrons) beside the passive truth, own scales."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    shots = [s for s in result["shots"] if not s.skipped and not s.lux_units]
    if not shots:
        return None
    scene = result["scene"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    fig.subplots_adjust(left=0.01, right=0.9, bottom=0.04, top=0.84, wspace=0.5)
    truth = scene.illuminance_lux(result["instants_s"][0])
    im0 = axes[0].imshow(truth, cmap=LUX_CMAP, norm=_lux_norm(result), interpolation="nearest")
    axes[0].set_title("passive light on the sensor (truth, lux)", fontsize=9)
    # each colour bar hugs its own image (different quantities: lux, photoelectrons)
    fig.colorbar(im0, cax=axes[0].inset_axes([1.03, 0, 0.035, 1]), label="illuminance (lux, log scale)")
    e = np.maximum(shots[0].estimates[0].lux, 0.1)
    floor = max(0.1, float(np.percentile(e, 1)))
    im1 = axes[1].imshow(e, cmap="viridis", norm=LogNorm(vmin=floor, vmax=max(1.0, float(e.max()))),
                         interpolation="nearest")
    axes[1].set_title(f"{shots[0].label}: one frame", fontsize=9)
    fig.colorbar(im1, cax=axes[1].inset_axes([1.03, 0, 0.035, 1]), extend="min",
                 label=f"laser-return photoelectrons\nper pixel (e⁻, log; ≤ {floor:.2g} at the bottom)")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle("Range gating sees the laser's own light, not lux: compare the targets' contrast-to-noise",
                 fontsize=10)
    return fig


# ------------------------------------------------------------------ HTML
def _fmt(v) -> str:
    if v is None:
        return "—"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return f"{int(v):d}"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not math.isfinite(v):
            return "n/a"
        if v == 0:
            return "0"
        text = f"{v:.4g}"
        if "e" in text:  # no exponent next to plain decimals: fixed point, 4 significant figures
            text = f"{v:.{max(0, 3 - math.floor(math.log10(abs(v))))}f}"
        return text
    if isinstance(v, dict):
        return ", ".join(f"{k}: {_fmt(x)}" for k, x in v.items())
    if isinstance(v, (list, tuple)):
        text = ", ".join(_fmt(x) for x in v[:8])
        return f"[{text}{', …' if len(v) > 8 else ''}]"
    return str(v)


def _flatten(d, prefix=""):
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict) and len(v) <= 30:
            yield from _flatten(v, name + ".")
        else:
            yield name, v


def _img(png_path: Path, alt: str) -> str:
    data = base64.b64encode(png_path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px auto;max-width:1280px;
color:#1a1a1a;line-height:1.45;padding:0 16px}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;font-size:.85em;margin:.6em 0}td,th{border:1px solid #ccc;padding:3px 7px;
text-align:right}th{background:#f0f0f0}td:first-child,th:first-child{text-align:left}
img{max-width:100%;height:auto;border:1px solid #ddd;margin:.4em 0}.note{color:#555;font-size:.9em}
.sensor{border:1px solid #ddd;border-radius:6px;padding:.3em 1em;margin:1em 0;background:#fafafa}
.params td{text-align:left;font-family:ui-monospace,monospace;font-size:.9em}ul.verdict li{margin:.3em 0}
"""


def write_report(result, out_dir, command: str = "", started_s: float | None = None) -> dict:
    """Write report.html, metrics.json and figures/*.png in ``out_dir``; return the metrics document."""
    out = Path(out_dir)
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    scene = result["scene"]
    shots = result["shots"]
    instants = result["instants_s"]
    paths = {}
    has_lux = any(not s.skipped and s.lux_units for s in shots)
    if hasattr(scene, "landmarks"):
        save_figure(figs / "scene.png", figure_scene(result))
        paths["scene"] = figs / "scene.png"
    if has_lux:
        save_figure(figs / "dilemma.png", figure_dilemma(result))
        paths["dilemma"] = figs / "dilemma.png"
    for i, t in enumerate(instants):
        save_figure(figs / f"images_{i}_{t * 1e3:.2f}ms.png", figure_instant(result, i))
        paths[f"images_{i}"] = figs / f"images_{i}_{t * 1e3:.2f}ms.png"
        if has_lux:
            save_figure(figs / f"errors_{i}_{t * 1e3:.2f}ms.png", figure_errors(result, i))
            paths[f"errors_{i}"] = figs / f"errors_{i}_{t * 1e3:.2f}ms.png"
    if result.get("vision"):
        from viform.measure.vision_comparison import figure_tracks

        save_figure(figs / "tracks.png", figure_tracks(result["vision"]))
        paths["tracks"] = figs / "tracks.png"
    gated = figure_gated(result)
    if gated is not None:
        save_figure(figs / "gated.png", gated)
        paths["gated"] = figs / "gated.png"

    spike_note = next((s.parameters["exposure_note"] for s in shots
                       if not s.skipped and "exposure_note" in s.parameters), None)
    if started_s is not None:  # one wall time, from the command's start (compilation included) to here
        result["run_time_s"] = time.perf_counter() - started_s
    doc = {
        "scene": scene.describe(), "duration_s": result["duration_s"], "instants_s": instants,
        "demand": result["demand"], "command": command,
        "metric_units": {k: u for k, (_, u) in cmp.METRICS.items()},
        "sensors": {s.key: {"label": s.label, "description": s.description, "skipped": s.skipped,
                            "metrics": s.metrics, "parameters": s.parameters} for s in shots},
        "verdict": result["verdict"], "run_time_s": result.get("run_time_s"),
        "run_time_note": RUN_TIME_NOTE, "spike_exposure": spike_note,
        "sensor_times_s": result["timings_s"],
    }
    if result.get("vision"):
        from viform.measure.vision_comparison import vision_json

        doc["vision"] = vision_json(result["vision"])
    doc = finite_json(doc)
    write_json(out / "metrics.json", doc)

    e = html.escape
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>viform compare: {e(scene.name)}"
             f"</title><style>{_CSS}</style></head><body>"]
    d = result["demand"]
    parts.append(f"<h1>One scene, every sensor: '{e(scene.name)}'</h1>")
    demand_text = ""
    if d:
        def lux(v):
            return f"{v:,.0f}" if v >= 1000 else f"{v:.3g}"

        demand_text = (f" The scene spans {lux(d['min_lux'])}–{lux(d['max_lux'])} lux "
                       f"({d['dynamic_range_db']:.0f} dB)")
        if math.isfinite(d["time_resolution_s"]):
            demand_text += (f", its fastest edge moves {d['max_speed_px_per_s']:.0f} px/s (one pixel every "
                            f"{d['time_resolution_s'] * 1e6:.0f} µs)")
        if d.get("flicker_hz"):
            demand_text += f", and an LED flickers at {d['flicker_hz']:g} Hz"
        demand_text += "."
    parts.append(f"<p class='note'>{size_text(scene.height, scene.width, 'pixels')}, "
                 f"{result['duration_s'] * 1e3:g} ms clip, "
                 f"images compared at {', '.join(f'{t * 1e3:.2f} ms' for t in instants)}.{e(demand_text)} "
                 f"Every sensor sees the same light (illuminance on the sensor plane) and is used at its "
                 f"documented settings.{' Command: <code>' + e(command) + '</code>.' if command else ''}"
                 + (f" Wall time {result['run_time_s']:.1f} s ({RUN_TIME_NOTE})." if result.get("run_time_s") else "")
                 + "</p>")
    if spike_note:
        parts.append(f"<p class='note' id='spike-exposure'>{e(spike_note['text'])}</p>")
    if "scene" in paths:
        parts.append(_img(paths["scene"], "the scene with its parts named"))
    parts.append("<section id='verdict'><h2>Who wins on what</h2><ul class='verdict'>")
    parts += [f"<li>{e(line)}</li>" for line in result["verdict"]]
    parts.append("</ul><p class='note'>Derived from the metrics below each time the report is made.</p></section>")

    parts.append("<section id='metrics'><h2>Metrics against the truth</h2><table><tr><th>sensor</th>")
    parts += [f"<th>{e(cmp.METRICS[k][0])}<br><span class='note'>{e(_unit(k))}</span></th>" for k in cmp.METRICS]
    parts.append("</tr>")
    for s in shots:
        if s.skipped:
            continue
        parts.append(f"<tr data-sensor='{e(s.key)}'><td>{e(s.label)}</td>")
        parts += [f"<td data-metric='{k}'>{_fmt(_shown(k, s.metrics.get(k)))}</td>" for k in cmp.METRICS]
        parts.append("</tr>")
    parts.append("</table><p class='note'>PSNR and SSIM on log10-lux over the scene's range; saturated = at "
                 "the pixel's ceiling; under-exposed = below its noise floor (SNR &lt; 1) or no spike; edge width = "
                 "10–90 % of the moving vehicle's leading edge; flicker error = |estimate − truth| of the PWM "
                 "LED over its on/off swing; DR captured = 20·lg(max/min) of the true light rendered within a "
                 "factor of 2; latency = worst-case time from a light change to an image showing it; "
                 "integration time = the light each image integrates (median interval, where the scene moves, "
                 "for the spike camera's interval images: a dim pixel's interval is longer, which is what blurs "
                 "their edges); frame interval = time from one image to the next (a sensor with a short "
                 "integration but a long frame interval sees motion sharply, but seldom). n/a: not defined for "
                 "this sensor or scene, or no single clean edge in the "
                 "image (several exposures of the moving edge overlaid, as in the overflow pixel).</p></section>")

    if "tracks" in paths:
        from viform.measure.vision_comparison import vision_html

        parts.append(vision_html(result["vision"], _img(paths["tracks"], "tracks over time against the truth")))
    if "dilemma" in paths:
        parts.append("<section id='dilemma'><h2>The dilemma: time resolution against dynamic range</h2>")
        parts.append(_img(paths["dilemma"], "time resolution against dynamic range"))
        parts.append("</section>")
    parts.append("<section id='images'><h2>Images at the chosen instants</h2>"
                 "<p class='note'>A frame camera shows the frame exposing at that instant, or else the last "
                 "frame it took (as a display holds it); the panel title says which light it integrated.</p>")
    for i, t in enumerate(instants):
        parts.append(f"<h3 id='instant-{i}'>t = {t * 1e3:.2f} ms</h3>")
        parts.append(_img(paths[f"images_{i}"], f"images at {t * 1e3:.2f} ms"))
        if f"errors_{i}" in paths:
            parts.append(_img(paths[f"errors_{i}"], f"error maps at {t * 1e3:.2f} ms"))
    if "gated" in paths:
        parts.append(_img(paths["gated"], "gated camera frame"))
    parts.append("</section><section id='sensors'><h2>Sensors and their parameters</h2>")
    for s in shots:
        parts.append(f"<div class='sensor' id='sensor-{e(s.key)}'><h3>{e(s.label)}</h3>"
                     f"<p>{e(s.description)}</p>")
        if s.skipped:
            parts.append(f"<p><b>Not in this comparison:</b> {e(s.skipped)}</p></div>")
            continue
        parts.append("<table>" + "".join(
            f"<tr><td>{e(cmp.METRICS[k][0])}</td><td data-metric='{k}'>{_fmt(_shown(k, s.metrics.get(k)))} "
            f"{e(_unit(k))}</td></tr>" for k in cmp.METRICS))
        if "target_cnr" in s.metrics:
            parts.append("".join(f"<tr><td>contrast-to-noise, {e(n)}</td><td>{_fmt(v)}</td></tr>"
                                 for n, v in s.metrics["target_cnr"].items()))
        parts.append("</table><details><summary>parameters</summary><table class='params'>")
        parts += [f"<tr><td>{e(k)}</td><td>{e(_fmt(v))}</td></tr>" for k, v in _flatten(s.parameters)]
        parts.append("</table></details></div>")
    parts.append("</section><p class='note'>Made by viform compare; self-contained (no network).</p></body></html>")
    with atomic_open(out / "report.html", "w") as f:
        f.write("".join(parts))
    return doc


#: Metrics shown to people in other units than metrics.json keeps (factor, unit).
DISPLAY_UNITS = {"saturated_fraction": (100.0, "%"), "underexposed_fraction": (100.0, "%"),
                 "latency_s": (1e3, "ms"), "time_resolution_s": (1e3, "ms"), "frame_interval_s": (1e3, "ms")}
#: What the reported wall time covers.
RUN_TIME_NOTE = ("from the command's start to the report written: simulation, scoring and figures, and on a "
                 "first run the compiling of the simulation kernels")


def _unit(key: str) -> str:
    return DISPLAY_UNITS[key][1] if key in DISPLAY_UNITS else cmp.METRICS[key][1]


def _shown(key: str, v):
    """A metric in the unit people read (percent, ms); metrics.json keeps SI units and fractions."""
    if key in DISPLAY_UNITS and isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
        return float(v) * DISPLAY_UNITS[key][0]
    return v


def finite_json(obj):
    """``obj`` as plain JSON types with NaN/±inf as null (bare NaN is not valid JSON, RFC 8259)."""
    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {str(k): clean(x) for k, x in v.items()}
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v

    out = clean(json.loads(json.dumps(obj, default=_json_default)))
    json.dumps(out, allow_nan=False)  # proves it: raises if anything non-finite is left
    return out


def _json_default(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist() if v.size <= 64 else f"array{list(v.shape)}"
    if isinstance(v, Path):
        return str(v)
    return str(v)


def metrics_table(doc: dict) -> str:
    """A small console table: one row per sensor, key metrics with units, 3–4 significant figures."""
    cols = [("psnr_log_db", "PSNR dB"), ("ssim_log", "SSIM"), ("saturated_fraction", "sat %"),
            ("underexposed_fraction", "under %"), ("edge_width_px", "edge px"), ("flicker_error", "flicker"),
            ("dr_captured_db", "DR dB"), ("data_rate_mb_per_s", "MB/s"), ("latency_s", "latency ms"),
            ("time_resolution_s", "integr. ms"), ("frame_interval_s", "frame ms")]
    width = max([len(v["label"]) for v in doc["sensors"].values()] + [6])
    lines = [f"{'sensor':<{width}}  " + "  ".join(f"{h:>9}" for _, h in cols)]
    for v in doc["sensors"].values():
        if v["skipped"]:
            lines.append(f"{v['label']:<{width}}  not applicable: {v['skipped']}")
            continue
        # None: not defined for this sensor or scene (metrics.json holds null there)
        lines.append(f"{v['label']:<{width}}  " + "  ".join(
            f"{'n/a' if v['metrics'].get(k) is None else _fmt(_shown(k, v['metrics'][k])):>9}" for k, _ in cols))
    return "\n".join(lines)


def compare(scene_spec: str, out_dir, sensors=None, duration_s: float = 0.04, height: int = 64,
            width: int = 128, seed: int = 0, instants_s=None, progress: bool = True, command: str = "",
            scene_options: dict | None = None, started_s: float | None = None, settings: dict | None = None,
            on_valid=None) -> dict:
    """Load the scene, run the comparison, write the report; return the metrics document.

    ``on_valid``: see :func:`run_comparison`.

    ``started_s``: ``time.perf_counter()`` at the command's start; the reported wall time runs from it.
    ``settings``: {sensor name: {parameter: value}} (see :func:`run_comparison`).
    """
    from viform.light.catalog import BUILTIN_SCENES, builtin_scene, load_scene

    height = check_int("--height", height, 32)
    width = check_int("--width", width, 48)
    seed = check_int("--seed", seed, 0)
    check_positive("--duration", duration_s)
    keys = check_sensors(sensors)
    if scene_spec in BUILTIN_SCENES:
        scene = builtin_scene(scene_spec, height, width, **(scene_options or {}))
    else:
        scene = load_scene(scene_spec, height, width, resize=True, settings=scene_options or None)
    started = time.perf_counter() if started_s is None else started_s
    result = run_comparison(scene, duration_s, keys, instants_s, seed, progress, settings, on_valid)
    return write_report(result, out_dir, command, started_s=started)
