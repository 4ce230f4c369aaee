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
    """(lux frames, report instants) of a frame camera's shot, or None when it has no frames."""
    raw = shot.raw
    if shot.key == "highspeed":
        from viform.isp.highspeed_pipeline import HighSpeedConfig

        ends = np.asarray(raw.frame_times_s, float)
        mids = ends - np.asarray(raw.exposure_s, float) / 2
        keep = ends <= duration_s + 1e-12
        ests = cmp.highspeed_estimates(raw, HighSpeedConfig(), mids[keep])
        return [e.lux for e in ests], ends[keep]
    if not hasattr(raw, "frames_dn"):
        return None
    n = cmp.complete_frames(raw, duration_s)
    if n == 0:
        return None
    kind = {"seed001-2seg": "segmented", "seed001-3seg": "segmented", "seed003-overflow": "overflow"}.get(shot.key,
                                                                                                         "linear")
    sensor = cmp.make_compare_sensor(shot.key)
    mids = raw.start_times_s[:n] + raw.exposure_s[:n] / 2
    ests = cmp.frame_estimates(sensor, raw, mids, kind, duration_s)
    return [e.lux for e in ests], raw.start_times_s[:n] + raw.exposure_s[:n]


def vision_scores(result) -> dict | None:
    """Track the scene's objects with every sensor of a comparison ``result``; None without object truth.

    Returns
    -------
    dict
        sensor key → ``{"label", "frame_rate_hz", "frames", "scores"}`` (or ``"skipped"``), plus
        ``"truth"`` (the true tracks at 1 ms, for the figure) under the key ``"_truth"``.
    """
    from viform.vision import motchallenge as mot
    from viform.vision.metrics import score_tracking
    from viform.vision.tracking import track_frames, track_spikes

    scene = result["scene"]
    if "objects" not in scene.truth_kinds():
        return None
    duration_s = result["duration_s"]
    out = {}
    done_spike = False
    for shot in result["shots"]:
        if shot.skipped or shot.key == "gated":
            continue
        if shot.key.startswith("spike"):
            if done_spike:
                continue
            done_spike = True
            stream = shot.raw
            res = track_spikes(stream, SPIKE_STEP_TICKS)
            tick_s = 1.0 / stream.clock_hz
            label = shot.label.split(" · ")[0] + f", tracked every {SPIKE_STEP_TICKS} ticks"
            key, rate = "spike", stream.clock_hz / SPIKE_STEP_TICKS
        else:
            frames = _frames_of(shot, duration_s)
            if frames is None or len(frames[1]) == 0:
                out[shot.key] = {"label": shot.label, "skipped": "no complete frame in the clip"}
                continue
            tick_s = 1.0 / 40_000.0  # the spike camera's tick: the same time constants in seconds
            res = track_frames(frames[0], frames[1], tick_s=tick_s)
            key, label, rate = shot.key, shot.label, shot.frame_rate_hz
        gt = mot.gt_rows(scene, res.times_s)
        scores = score_tracking(gt, res.rows, res.times_s, 1.0 / tick_s)
        out[key] = {"label": label, "frame_rate_hz": float(rate), "frames": int(res.times_s.size),
                    "scores": scores, "rows": res.rows, "times_s": res.times_s}
    times = np.arange(0.0, duration_s, 2.5e-4)
    out["_truth"] = {"rows": mot.gt_rows(scene, times), "times_s": times}
    return out


def vision_table(vision: dict) -> list[dict]:
    """One row per sensor: HOTA, MOTA, IDF1, ID switches, median latency (ms), objects never found."""
    rows = []
    for key, v in vision.items():
        if key.startswith("_"):
            continue
        if "skipped" in v:
            rows.append({"key": key, "label": v["label"], "skipped": v["skipped"]})
            continue
        s = v["scores"]
        lat = s["median_latency_found_s"]
        rows.append({"key": key, "label": v["label"], "frame_rate_hz": v["frame_rate_hz"], "hota": s["hota"],
                     "mota": s["mota"], "idf1": s["idf1"], "id_switches": s["id_switches"],
                     "median_latency_ms": None if lat is None else lat * 1e3,
                     "never_found": s["never_found"], "objects": len(s["objects"])})
    return rows


def vision_verdict(rows: list[dict]) -> list[str]:
    """Lines derived from the vision table: best HOTA, fastest to find, who loses which objects."""
    scored = [r for r in rows if "skipped" not in r]
    if not scored:
        return []
    best = max(scored, key=lambda r: r["hota"])
    lines = [f"Tracking: best HOTA {best['hota']:.2f} by {best['label']} (MOTA {best['mota']:.2f}, "
             f"IDF1 {best['idf1']:.2f})."]
    timed = [r for r in scored if r["median_latency_ms"] is not None]
    if timed:
        fast = min(timed, key=lambda r: r["median_latency_ms"])
        lines.append(f"Fastest to find the objects: {fast['label']}, median {fast['median_latency_ms']:.2f} ms "
                     "after each appeared.")
    lost = [r for r in scored if r["never_found"]]
    if lost:
        worst = max(lost, key=lambda r: len(r["never_found"]))
        lines.append(f"Most objects never matched: {worst['label']}, {len(worst['never_found'])} of "
                     f"{worst['objects']} (ids {', '.join(map(str, worst['never_found']))}).")
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


def vision_html(vision: dict, figure_img: str) -> str:
    """The report's vision section (table, verdict, figure)."""
    import html

    e = html.escape
    rows = vision_table(vision)
    parts = ["<section id='vision'><h2>Detection and tracking against the true objects</h2><table><tr>"
             "<th>sensor</th><th>reports per s</th><th>HOTA</th><th>MOTA</th><th>IDF1</th><th>ID switches</th>"
             "<th>median latency to find<br><span class='note'>ms</span></th><th>objects never found</th></tr>"]
    for r in rows:
        if "skipped" in r:
            parts.append(f"<tr data-sensor='{e(r['key'])}'><td>{e(r['label'])}</td><td colspan='7'>"
                         f"not tracked: {e(r['skipped'])}</td></tr>")
            continue
        lat = "never" if r["median_latency_ms"] is None else f"{r['median_latency_ms']:.2f}"
        never = ", ".join(map(str, r["never_found"])) or "none"
        parts.append(f"<tr data-sensor='{e(r['key'])}'><td>{e(r['label'])}</td><td>{r['frame_rate_hz']:,.0f}</td>"
                     f"<td>{r['hota']:.3f}</td><td>{r['mota']:.3f}</td><td>{r['idf1']:.3f}</td>"
                     f"<td>{r['id_switches']}</td><td>{lat}</td><td>{e(never)} of {r['objects']}</td></tr>")
    parts.append("</table><ul class='verdict'>")
    parts += [f"<li>{e(line)}</li>" for line in vision_verdict(rows)]
    parts.append("</ul><p class='note'>The same detection and association back end on every sensor's own output "
                 "(spikes, or frames turned into lux), with the same settings in seconds; each is scored at the "
                 "instants it reports, against the scene's exact boxes (HOTA, MOTA, IDF1 and ID switches from "
                 "TrackEval). Latency: from an object's appearance to the first reported box overlapping it. "
                 "The back end learns the background from the first frame and confirms a track after two "
                 "detections, so a camera that delivers fewer than three frames in the clip finds nothing.</p>")
    parts.append(figure_img + "</section>")
    return "".join(parts)


def vision_console(vision: dict) -> str:
    """Console lines of the vision table."""
    rows = vision_table(vision)
    width = max([len(r["label"]) for r in rows] + [6])
    lines = [f"{'tracking':<{width}}  {'HOTA':>6} {'MOTA':>7} {'IDF1':>6} {'IDsw':>5} {'latency ms':>10}  never found"]
    for r in rows:
        if "skipped" in r:
            lines.append(f"{r['label']:<{width}}  not tracked: {r['skipped']}")
            continue
        lat = "never" if r["median_latency_ms"] is None else f"{r['median_latency_ms']:.2f}"
        lines.append(f"{r['label']:<{width}}  {r['hota']:>6.3f} {r['mota']:>7.3f} {r['idf1']:>6.3f} "
                     f"{r['id_switches']:>5} {lat:>10}  {', '.join(map(str, r['never_found'])) or 'none'}")
    return "\n".join(lines + [f"- {line}" for line in vision_verdict(rows)])


def vision_json(vision: dict) -> dict:
    """What metrics.json keeps: the table rows and each sensor's per-object scores."""
    return {"table": vision_table(vision),
            "objects": {k: v["scores"]["objects"] for k, v in vision.items()
                        if not k.startswith("_") and "scores" in v},
            "verdict": vision_verdict(vision_table(vision))}
