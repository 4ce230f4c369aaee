"""The comparison's vision section: every sensor tracks the scene's objects, scored against exact truth.

One back end (:mod:`viform.vision.tracking`: change front end, connected components, Kalman +
Hungarian tracks, the same parameters in seconds for every sensor — nothing tuned per sensor)
runs on each sensor's own output: the spike stream every :data:`SPIKE_STEP_TICKS` ticks, each
frame camera on its frames converted to lux by the comparison's inverse response
(:func:`viform.measure.comparison.frame_estimates`), at its own frame rate. Each sensor is scored
against the truth at the instants it reports (the end of each step or exposure: the earliest its
output exists) — interpolated tracks are not truth. Scores: HOTA, MOTA, IDF1, ID switches
(TrackEval), the median latency to find an object, and the objects never matched.
"""

from __future__ import annotations

import numpy as np

from viform.measure import comparison as cmp

#: Output step of the spike tracker in the comparison, ticks (4 kHz at 40 kHz).
SPIKE_STEP_TICKS = 10


def _frames_of(shot, duration_s):
    """(lux frames, report instants, measured pixels, saturated pixels) of a frame camera's shot, or None.

    Each frame that ends in the clip, in lux (the sensor's own inverse response), reported at the end
    of its exposure (the earliest it exists). A pixel is measured where its frame is not under the
    noise floor; a saturated one is at least as bright as its value.
    """
    raw = shot.raw
    if shot.family not in ("frame", "segmented", "overflow", "highspeed") or not hasattr(raw, "frames_dn"):
        return None
    n = cmp.complete_frames(raw, duration_s)
    if n == 0:
        return None
    starts, exposures = raw.start_times_s[:n], raw.exposure_s[:n]
    ests = cmp.light_estimates(shot.family, shot.sensor, raw, starts + exposures / 2, duration_s=duration_s)
    return ([e.lux for e in ests], starts + exposures, [~e.underexposed for e in ests],
            [e.saturated for e in ests])


def _frame_detectability(shot):
    """The frame sensor's detectability (contrast against its noise over its exposure), or None."""
    from viform.vision.detectability import FrameDetectability

    raw = shot.raw
    exposures = np.asarray(getattr(raw, "exposure_s", []), float).ravel()
    if exposures.size == 0:
        return None
    exposure = float(np.median(exposures))  # (past an auto-exposure's start-up)
    p = getattr(shot.sensor, "parameters", None)
    step_e = 0.0
    if shot.family == "highspeed":
        step_e = (1 << (p.adc_bits - 8)) / p.system_gain_dn_per_e  # one 8-bit grey level, e⁻
    try:
        return FrameDetectability(p.optics.electrons_per_lux_second, exposure,
                                  float(np.hypot(p.read_noise_electrons, step_e / np.sqrt(12.0))),
                                  p.full_well_electrons)
    except AttributeError:
        return None


#: Frames the back end needs to see motion: three to learn the background and one more (before
#: that, only what stands out from the background around it is found).
FRAMES_NEEDED = 4


def _causes(scores, gt, frames: int, exposure_s: float | None, scene) -> dict:
    """For each object never matched, the physical reason where there is one (else the tracker's miss)."""
    out = {}
    for oid in scores["never_found"]:
        rows = gt[(gt[:, 1] == oid) & (gt[:, 6] > 0)]
        detect = rows[:, 9][rows[:, 9] >= 0] if len(rows) else np.zeros(0)
        spec = next((sp for sp in getattr(scene, "specs", ()) if sp.object_id == oid), None)
        if frames < FRAMES_NEEDED:
            out[oid] = f"only {frames} frame(s) in the clip (the back end sees motion from the {FRAMES_NEEDED}th)"
        elif detect.size and detect.max() < 1.0:
            out[oid] = f"its contrast is under the noise (detectability at most {detect.max():.2f} of the 1 needed)"
        elif exposure_s is not None and spec is not None:
            v = float(np.hypot(*scene.velocity_px_per_s(spec, float(scene.t_ref_s))))
            w, h = scene.size_px(spec)
            blur = v * exposure_s
            if blur > 0.5 * min(w, h):
                out[oid] = (f"the exposure's blur: {exposure_s * 1e3:.3g} ms at {v:,.0f} px/s smears it over "
                            f"{blur:.3g} px (it is {min(w, h):.3g} px across)")
        out.setdefault(oid, "missed by the tracker (the sensor shows it)")
    return out


def vision_scores(result) -> dict | None:
    """Track the scene's objects with every sensor of a comparison ``result``; None without object truth.

    Each sensor is scored against truth rows that carry its own detectability (spike sensors: the
    charge an object delivers against Q; frame sensors: its contrast against the noise over the
    exposure), over all objects and over the detectable ones, and every object it never finds is
    given a cause (:func:`_causes`).

    Parameters
    ----------
    result : dict
        A comparison's result (:func:`viform.report.compare_report.run_comparison`), shots included.

    Returns
    -------
    dict
        sensor key → ``{"label", "frame_rate_hz", "frames", "scores", "causes"}`` (or ``"skipped"``),
        plus ``"truth"`` (the true tracks at 1 ms, for the figure) under the key ``"_truth"``.
    """
    from viform.vision import motchallenge as mot
    from viform.vision.detectability import spike_detectability_of
    from viform.vision.metrics import score_tracking
    from viform.vision.tracking import track_frames, track_spikes

    scene = result["scene"]
    if "objects" not in scene.truth_kinds():
        return None
    duration_s = result["duration_s"]
    out = {}
    done_spike = False
    for shot in result["shots"]:
        if shot.skipped or shot.family == "gated":
            continue
        exposure = None
        if shot.family == "spike":
            if done_spike:
                continue
            done_spike = True
            stream = shot.raw
            res = track_spikes(stream, SPIKE_STEP_TICKS)
            tick_s = 1.0 / stream.clock_hz
            label = shot.label.split(" · ")[0] + f", tracked every {SPIKE_STEP_TICKS} ticks"
            key, rate = shot.name or "spike", stream.clock_hz / SPIKE_STEP_TICKS
            detect = spike_detectability_of(stream)
        else:
            frames = _frames_of(shot, duration_s)
            if frames is None or len(frames[1]) == 0:
                out[shot.key] = {"label": shot.label, "skipped": "no complete frame in the clip"}
                continue
            tick_s = 1.0 / 40_000.0  # the spike camera's tick: the same time constants in seconds
            res = track_frames(frames[0], frames[1], tick_s=tick_s, measured=frames[2], saturated=frames[3])
            key, label, rate = shot.key, shot.label, shot.frame_rate_hz
            detect = _frame_detectability(shot)
            exposure = float(np.median(np.asarray(shot.raw.exposure_s, float)))
        gt = mot.gt_rows(scene, res.times_s, detectability=detect)
        scores = score_tracking(gt, res.rows, res.times_s, 1.0 / tick_s)
        out[key] = {"label": label, "frame_rate_hz": float(rate), "frames": int(res.times_s.size),
                    "scores": scores, "rows": res.rows, "times_s": res.times_s,
                    "causes": _causes(scores, gt, int(res.times_s.size), exposure, scene)}
    times = np.arange(0.0, duration_s, 2.5e-4)
    out["_truth"] = {"rows": mot.gt_rows(scene, times), "times_s": times}
    return out


def vision_table(vision: dict) -> list[dict]:
    """One row per sensor: HOTA (all objects and detectable ones), MOTA, IDF1, ID switches, latency, misses."""
    rows = []
    for key, v in vision.items():
        if key.startswith("_"):
            continue
        if "skipped" in v:
            rows.append({"key": key, "label": v["label"], "skipped": v["skipped"]})
            continue
        s = v["scores"]
        lat = s["median_latency_found_s"]
        d = s.get("detectable")
        rows.append({"key": key, "label": v["label"], "frame_rate_hz": v["frame_rate_hz"], "frames": v["frames"],
                     "hota": s["hota"], "mota": s["mota"], "idf1": s["idf1"], "id_switches": s["id_switches"],
                     "hota_detectable": None if d is None else d["hota"],
                     "median_latency_ms": None if lat is None else lat * 1e3,
                     "never_found": s["never_found"], "objects": len(s["objects"]),
                     "causes": {int(k): c for k, c in v.get("causes", {}).items()}})
    return rows


def _named(rows: list[dict], limit: int = 3) -> str:
    """The sensors of ``rows`` by name: all of them, or the first ``limit`` and how many more."""
    labels = [r["label"] for r in rows]
    if len(labels) <= limit:
        return ", ".join(labels)
    return f"{', '.join(labels[:limit])} and {len(labels) - limit} more"


def vision_verdict(rows: list[dict]) -> list[str]:
    """Lines derived from the vision table: best HOTA, fastest to find, who loses which objects (ties named)."""
    scored = [r for r in rows if "skipped" not in r]
    if not scored:
        return []
    lines = []
    # a sensor with too few frames to see motion is scored at its few instants; it is not ranked
    ranked = [r for r in scored if r.get("frames", FRAMES_NEEDED) >= FRAMES_NEEDED] or scored
    few = [r for r in scored if r not in ranked]
    top = max(r["hota"] for r in ranked)
    best = [r for r in ranked if abs(r["hota"] - top) < 5e-4]
    if len(best) == 1:
        b = best[0]
        lines.append(f"Tracking: best HOTA {b['hota']:.2f} by {b['label']} (MOTA {b['mota']:.2f}, "
                     f"IDF1 {b['idf1']:.2f}).")
    else:
        lines.append(f"Tracking: best HOTA {top:.2f}, a {len(best)}-way tie: {_named(best)}.")
    if few:
        lines.append(f"Not ranked (fewer than {FRAMES_NEEDED} frames in the clip, so no motion to track; scored at "
                     f"their {'/'.join(str(r['frames']) for r in few)} instants only): {_named(few)}.")
    timed = [r for r in ranked if r["median_latency_ms"] is not None and len(r["never_found"]) < r["objects"]]
    if timed:
        low = min(r["median_latency_ms"] for r in timed)
        fast = [r for r in timed if abs(r["median_latency_ms"] - low) < 5e-4]
        who = fast[0]["label"] if len(fast) == 1 else f"a {len(fast)}-way tie: {_named(fast)}"
        lines.append(f"Fastest to find the objects: {who}, median {low:.2f} ms after each appeared.")
    lost = [r for r in scored if r["never_found"]]
    if lost:
        most = max(len(r["never_found"]) for r in lost)
        worst = [r for r in lost if len(r["never_found"]) == most]
        if len(worst) == 1:
            w = worst[0]
            lines.append(f"Most objects never matched: {w['label']}, {most} of {w['objects']} "
                         f"(ids {', '.join(map(str, w['never_found']))}).")
        else:
            counts = {w["objects"] for w in worst}
            of = f"{most} of {counts.pop()}" if len(counts) == 1 else f"{most} objects"
            lines.append(f"Most objects never matched: {of}, a {len(worst)}-way tie: {_named(worst)}.")
    for r in lost:  # the physical cause where one sensor finds nothing, with its number
        causes = r.get("causes", {})
        if len(r["never_found"]) == r["objects"] and causes:
            first = causes[r["never_found"][0]]
            same = all(c == first for c in causes.values())
            lines.append(f"{r['label']} finds nothing: " + (first if same else
                         "; ".join(f"object {k}: {c}" for k, c in sorted(causes.items()))) + ".")
    return lines


def figure_tracks(vision: dict):
    """Tracks over time against truth: box-centre x (px) against time (ms), one panel per sensor."""
    import matplotlib.pyplot as plt

    keys = [k for k, v in vision.items() if not k.startswith("_") and "skipped" not in v]
    n = max(1, len(keys))
    cols = min(3, n)
    rows_n = (n + cols - 1) // cols
    fig, axs = plt.subplots(rows_n, cols, figsize=(5.2 * cols, 3.2 * rows_n), squeeze=False, sharey=True)
    truth = vision["_truth"]
    cmap = plt.get_cmap("tab10")
    for ax, key in zip(axs.ravel(), keys, strict=False):
        gt, gt_t = truth["rows"], truth["times_s"]
        for k, oid in enumerate(np.unique(gt[:, 1])):
            sel = gt[:, 1] == oid
            ax.plot(gt_t[gt[sel, 0].astype(int) - 1] * 1e3, gt[sel, 2] + gt[sel, 4] / 2, "-", color="0.75", lw=3,
                    label="truth" if k == 0 else None, zorder=1)
        v = vision[key]
        rows, times = v["rows"], v["times_s"]
        for tid in np.unique(rows[:, 1]) if len(rows) else []:
            sel = rows[:, 1] == tid
            ax.plot(times[rows[sel, 0].astype(int) - 1] * 1e3, rows[sel, 2] + rows[sel, 4] / 2, ".", ms=2.5,
                    color=cmap(int(tid) % 10), zorder=2)
        s = v["scores"]
        ax.set_title(f"{v['label']}\nHOTA {s['hota']:.2f}, MOTA {s['mota']:.2f}, IDF1 {s['idf1']:.2f}", fontsize=8)
        ax.set_xlabel("time (ms)")
        ax.set_ylabel("box centre x (px)")
        ax.legend(loc="upper right", fontsize=7)
    for ax in axs.ravel()[len(keys):]:
        ax.axis("off")
    fig.suptitle("Tracks over time against the truth (grey): each colour one track id", fontsize=10)
    fig.tight_layout()
    return fig


def _hota_detectable(r) -> str:
    return "—" if r.get("hota_detectable") is None else f"{r['hota_detectable']:.3f}"


def _never(r) -> str:
    """Objects never found, grouped by their cause (where it is physical), and how many were in view."""
    if not r["never_found"]:
        return f"none of {r['objects']}"
    causes = r.get("causes", {})
    groups: dict[str, list] = {}
    for k in r["never_found"]:
        groups.setdefault(causes.get(k, ""), []).append(k)
    parts = [", ".join(map(str, ids)) + (f": {c}" if c and not c.startswith("missed") else "")
             for c, ids in groups.items()]
    return "; ".join(parts) + f" (of {r['objects']} in view)"


def vision_html(vision: dict, figure_img: str) -> str:
    """The report's vision section (table, verdict, figure)."""
    import html

    e = html.escape
    rows = vision_table(vision)
    parts = ["<section id='vision'><h2>Detection and tracking against the true objects</h2><table><tr>"
             "<th>sensor</th><th>reports per s</th><th>HOTA</th><th>HOTA, objects it shows</th><th>MOTA</th>"
             "<th>IDF1</th><th>ID switches</th><th>median latency to find<br><span class='note'>ms</span></th>"
             "<th>objects never found (why)</th></tr>"]
    for r in rows:
        if "skipped" in r:
            parts.append(f"<tr data-sensor='{e(r['key'])}'><td>{e(r['label'])}</td><td colspan='8'>"
                         f"not tracked: {e(r['skipped'])}</td></tr>")
            continue
        lat = "never" if r["median_latency_ms"] is None else f"{r['median_latency_ms']:.2f}"
        parts.append(f"<tr data-sensor='{e(r['key'])}'><td>{e(r['label'])}</td><td>{r['frame_rate_hz']:,.0f}</td>"
                     f"<td>{r['hota']:.3f}</td><td>{_hota_detectable(r)}</td><td>{r['mota']:.3f}</td>"
                     f"<td>{r['idf1']:.3f}</td><td>{r['id_switches']}</td><td>{lat}</td>"
                     f"<td>{e(_never(r))}</td></tr>")
    parts.append("</table><ul class='verdict'>")
    parts += [f"<li>{e(line)}</li>" for line in vision_verdict(rows)]
    parts.append("</ul><p class='note'>The same detection and association back end on every sensor's own output "
                 "(spikes, or frames turned into lux with the pixels under the noise floor or saturated marked), "
                 "with the same settings in seconds; each is scored at the instants it reports, against the "
                 "scene's exact boxes (HOTA, MOTA, IDF1 and ID switches from TrackEval). \u201cObjects it "
                 "shows\u201d: truth rows where the sensor's pixels hold under one threshold's charge of the object "
                 "(spikes) or its contrast is under the noise of one exposure (frames) need not be found. "
                 "Latency: from an object's appearance to the first reported box overlapping it. The frame back "
                 f"end learns its background from the median of three frames, so a camera that delivers fewer "
                 f"than {FRAMES_NEEDED} frames in the clip sees no motion: it finds at most the objects that stand "
                 "out from the background around them.</p>")
    parts.append(figure_img + "</section>")
    return "".join(parts)


def vision_console(vision: dict) -> str:
    """Console lines of the vision table."""
    rows = vision_table(vision)
    width = max([len(r["label"]) for r in rows] + [6])
    lines = [f"{'tracking':<{width}}  {'HOTA':>6} {'shown':>6} {'MOTA':>7} {'IDF1':>6} {'IDsw':>5} {'latency ms':>10}"
             "  never found"]
    for r in rows:
        if "skipped" in r:
            lines.append(f"{r['label']:<{width}}  not tracked: {r['skipped']}")
            continue
        lat = "never" if r["median_latency_ms"] is None else f"{r['median_latency_ms']:.2f}"
        lines.append(f"{r['label']:<{width}}  {r['hota']:>6.3f} {_hota_detectable(r):>6} {r['mota']:>7.3f} "
                     f"{r['idf1']:>6.3f} {r['id_switches']:>5} {lat:>10}  {_never(r)}")
    return "\n".join(lines + [f"- {line}" for line in vision_verdict(rows)])


def vision_json(vision: dict) -> dict:
    """What metrics.json keeps: the table rows and each sensor's per-object scores."""
    return {"table": vision_table(vision),
            "objects": {k: v["scores"]["objects"] for k, v in vision.items()
                        if not k.startswith("_") and "scores" in v},
            "verdict": vision_verdict(vision_table(vision))}
