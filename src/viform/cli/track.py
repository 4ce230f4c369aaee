"""CLI: ``viform track`` — detect and track moving objects in a spike file, score them against truth."""

from __future__ import annotations

import inspect
import json
from pathlib import Path

import click
import numpy as np

from viform._validate import ViformError, size_text
from viform.cli._common import open_source
from viform.cli.app import cli


def scene_from_metadata(metadata: dict):
    """The built-in scene a simulated stream was shot from (its sidecar records it), or None."""
    from viform.light.catalog import BUILTIN_SCENES, builtin_scene

    described = (metadata or {}).get("scene")
    if not isinstance(described, dict) or described.get("name") not in BUILTIN_SCENES:
        return None
    try:
        probe = builtin_scene(described["name"], int(described["height"]), int(described["width"]))
        accepted = inspect.signature(type(probe).__init__).parameters
        extra = {k: v for k, v in described.items() if k in accepted and k not in ("height", "width", "duration_s")}
        scene = builtin_scene(described["name"], int(described["height"]), int(described["width"]), **extra)
    except (ViformError, TypeError, ValueError, KeyError):
        return None
    return scene if "objects" in scene.truth_kinds() else None


def _overlay(path, background, result, gt, title):
    """Boxes and trails of every track (and the truth, dashed) on the stream's mean firing-rate image."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform._io import save_figure

    h, w = background.shape
    fig, ax = plt.subplots(figsize=(max(4.0, 8.0 * w / max(h, w)) + 1.2, max(3.0, 8.0 * h / max(h, w))))
    im = ax.imshow(background, cmap="gray", extent=(0, w, h, 0))
    fig.colorbar(im, ax=ax, label="mean firing rate (spikes per tick)", fraction=0.04)
    cmap = plt.get_cmap("tab10")
    if gt is not None and len(gt):
        for k, oid in enumerate(np.unique(gt[:, 1])):
            rows = gt[gt[:, 1] == oid]
            ax.plot(rows[:, 2] + rows[:, 4] / 2, rows[:, 3] + rows[:, 5] / 2, "--", color="w", lw=0.8,
                    label="truth (centres)" if k == 0 else None)
    rows = result.rows
    for tid in np.unique(rows[:, 1]) if len(rows) else []:
        r = rows[rows[:, 1] == tid]
        colour = cmap(int(tid) % 10)
        ax.plot(r[:, 2] + r[:, 4] / 2, r[:, 3] + r[:, 5] / 2, "-", color=colour, lw=1.2)
        x, y, bw, bh = r[-1, 2:6]
        ax.add_patch(plt.Rectangle((x, y), bw, bh, fill=False, ec=colour, lw=1.2))
        ax.text(x, y - 1, f"{int(tid)}", color=colour, fontsize=7)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    ax.set_title(title, fontsize=9)
    if gt is not None and len(gt):
        ax.legend(loc="lower right", fontsize=7)
    save_figure(path, fig)


@cli.command()
@click.argument("file", type=click.Path(exists=True))
@click.option("--every", "every", type=int, default=40, show_default=True,
              help="Report tracks every N ticks (N ≥ 1; 40 ticks = 1 ms at 40 kHz).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for results.txt (MOTChallenge: frame,id,x,y,w,h,conf,-1,-1,-1), seqinfo.ini, "
                   "overlay.png and, where the stream has truth, gt.txt and scores.json.")
@click.option("--truth", "truth_path", type=click.Path(exists=True, dir_okay=False), default=None,
              help="A MOTChallenge gt.txt to score against (default: the truth of the built-in scene the "
                   "file was simulated from, when its sidecar names one).")
@click.option("--scores/--no-scores", default=None,
              help="Score against the truth (default: when there is truth; --scores refuses a file without).")
@click.option("--height", type=int, default=None, help="Height of a .dat file.")
@click.option("--width", type=int, default=None, help="Width of a .dat file.")
@click.option("--clock-hz", type=float, default=None, help="Clock of a .dat/.npz file (default 40 kHz).")
@click.option("--no-flip", is_flag=True, help=".dat rows stored upright (some simulators).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary instead of the table.")
@click.option("--json-file", "json_file", type=click.Path(dir_okay=False), default=None,
              help="Also write the JSON summary to this file.")
def track(file, every, out_dir, truth_path, scores, height, width, clock_hz, no_flip, as_json, json_file):
    """Detect and track moving objects in the spike stream FILE, reporting every N ticks.

    A pixel counts as moving where its light differs from its own background level (static
    texture never does); neighbouring moving pixels form a detection; detections join tracks
    by predicted position (constant velocity), and a track coasts through short occlusions.
    Frame k of the results is output step k (ticks (k−1)·N … k·N − 1), exactly as in the
    truth's gt.txt, so any MOT evaluator scores the results directly.
    """
    from viform._io import check_json_file, check_output_folder, write_json
    from viform.vision import motchallenge as mot
    from viform.vision.metrics import score_tracking
    from viform.vision.tracking import track_spikes

    if every is None or every < 1:
        raise ViformError(f"--every = {every!r} is not allowed: give a whole number of ticks ≥ 1")
    if out_dir is not None:
        check_output_folder("--out", Path(out_dir).resolve())
    check_json_file(json_file)
    source = open_source(file, height, width, clock_hz, flip=not no_flip)
    if source.n_ticks < every:
        raise ViformError(f"--every = {every} is longer than the stream ({source.n_ticks} ticks): "
                          f"give --every ≤ {source.n_ticks}" if source.n_ticks else f"{file!r} holds no ticks")
    n_frames = source.n_ticks // every
    times = mot.step_times_s(n_frames, every, source.clock_hz, source.start_time_s)
    scene = None
    gt = classes = None
    per = 1  # result frames per truth frame
    notes = []
    if truth_path is not None:
        gt = mot.read_gt(truth_path)
        per, note = _align_truth(truth_path, gt, every, n_frames, source)
        notes += [note] if note else []
        truth_from = str(truth_path)
    else:
        scene = scene_from_metadata(source.metadata)
        truth_from = None if scene is None else f"built-in scene {scene.name!r} from the file's sidecar"
    if scores and gt is None and scene is None:
        raise ViformError(f"--scores: {file!r} carries no object truth (its sidecar names no built-in scene with "
                          "objects); give --truth gt.txt, or drop --scores")
    if scene is not None and (scene.height, scene.width) != (source.height, source.width):
        raise ViformError(f"the file's scene is {size_text(scene.height, scene.width)} but the stream is "
                          f"{size_text(source.height, source.width)}: give --truth gt.txt")
    if scene is not None:
        from viform.vision.detectability import spike_detectability_of

        gt, classes = mot.gt_rows(scene, times, detectability=spike_detectability_of(source),
                                  start_time_s=source.start_time_s, return_class_ids=True)
    if gt is not None and not len(gt):
        if scores:
            raise ViformError(f"--scores: the truth ({truth_from}) holds no object in view during the stream: "
                              "there is nothing to score; drop --scores")
        notes.append(f"the truth ({truth_from}) holds no object in view during the stream: not scored")
        gt = None
    want_scores = gt is not None and scores is not False

    result = track_spikes(source, every)
    mean_rate = result.spike_counts / max(source.n_ticks, 1)
    from viform.imaging.support import support_from_rates
    from viform.vision.tracking import TrackerParameters

    # the tracker follows each pixel's light by its intervals: one (2 spikes) per background time constant
    warning = support_from_rates(mean_rate, round(TrackerParameters().background_ticks), 2, source.n_ticks).warning(
        "tracking", "brighten the scene or lower the threshold Q (simulate -q / --threshold-level)")
    if warning:
        click.echo(warning, err=True)

    summary = {"file": str(file), "every_ticks": every, "frames": n_frames, "frame_rate_hz": source.clock_hz / every,
               "tracks": int(len(np.unique(result.rows[:, 1]))) if len(result.rows) else 0,
               "boxes": int(len(result.rows)), "detections": result.detections, "truth": truth_from,
               "notes": notes, "files": []}
    if want_scores:
        rows, score_times = result.rows, times
        if per > 1:  # scored at the truth's frames: result frame k·per is truth frame k
            rows = rows[rows[:, 0] % per == 0].copy()
            rows[:, 0] //= per
            score_times = times[per - 1::per]
        s = score_tracking(gt, rows, score_times, source.clock_hz, source.start_time_s)
        summary["scores"] = s
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files = [mot.write_results(out / "results.txt", result.rows),
                 mot.write_seqinfo(out / "seqinfo.ini", name=Path(file).stem, n_frames=n_frames, step_ticks=every,
                                   clock_hz=source.clock_hz, width=source.width, height=source.height,
                                   start_time_s=source.start_time_s,
                                   classes=classes)]
        if gt is not None and truth_path is None:
            files.append(mot.write_gt(out / "gt.txt", gt))
        _overlay(out / "overlay.png", mean_rate, result, gt if per == 1 else None,
                 f"{Path(file).name}: tracks every {every} ticks (colour, last box), truth dashed")
        files.append(out / "overlay.png")
        if want_scores:
            write_json(out / "scores.json", summary["scores"])
            files.append(out / "scores.json")
        summary["files"] = [str(f) for f in files]
    if json_file is not None:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=float))
        return
    click.echo(f"tracked {file}: {n_frames} frames of {every} ticks ({summary['frame_rate_hz']:g} per second), "
               f"{summary['tracks']} tracks, {summary['boxes']} boxes")
    for note in notes:
        click.echo(f"note: {note}")
    if want_scores:
        _print_scores(summary["scores"], truth_from)
    if summary["files"]:
        click.echo(f"wrote {len(summary['files'])} file(s) to {out_dir}")


def _align_truth(truth_path, gt, every: int, n_frames: int, source):
    """Result frames per truth frame (1, or the whole ratio of the truth's step to ``--every``) and a note.

    The truth's ``seqinfo.ini`` (beside gt.txt or one folder up, the MOTChallenge layout) records its
    step in ticks; results are scored only at instants the truth has. Without it the truth's frames
    are taken as steps of ``--every``, which is refused where the truth runs past the stream's steps.
    """
    from viform.vision import motchallenge as mot

    folder = Path(truth_path).resolve().parent
    info_path = next((p for p in (folder / "seqinfo.ini", folder.parent / "seqinfo.ini") if p.is_file()), None)
    last = int(gt[:, 0].max()) if len(gt) else 0
    if info_path is None:
        if last > n_frames:
            raise ViformError(f"--truth {str(truth_path)!r} has frames up to {last} but the stream has {n_frames} "
                              f"steps of --every {every} ticks, and no seqinfo.ini beside it records its step: "
                              "give the --every its frames were written with")
        return 1, (f"no seqinfo.ini beside {str(truth_path)!r}: its frames are taken as steps of --every {every} "
                   "ticks")
    info = mot.read_seqinfo(info_path)
    step, clock = info["step_ticks"], info["clock_hz"]
    if (info["width"], info["height"]) != (source.width, source.height):
        raise ViformError(f"--truth: {str(info_path)!r} is for {size_text(info['height'], info['width'])} images but "
                          f"the stream "
                          f"is {size_text(source.height, source.width)}")
    if clock is not None and abs(clock - source.clock_hz) > 1e-6 * source.clock_hz:
        raise ViformError(f"--truth: {str(info_path)!r} records a {clock:g} Hz clock but the stream's is "
                          f"{source.clock_hz:g} Hz")
    if step is None:
        step = int(round(source.clock_hz / info["frame_rate_hz"])) if info["frame_rate_hz"] > 0 else every
    if step == every:
        return 1, None
    if step % every:
        raise ViformError(f"--truth: {str(info_path)!r} records {step} ticks a frame, which --every {every} does "
                          f"not divide: frames would be scored at the wrong instants; give --every {step} "
                          "(or a divisor of it)")
    return step // every, (f"the truth has a frame every {step} ticks: results are scored at those instants "
                           f"(one result frame in {step // every})")


def _print_scores(s: dict, truth_from: str) -> None:
    click.echo(f"against {truth_from}: HOTA {s['hota']:.3f} (DetA {s['deta']:.3f}, AssA {s['assa']:.3f}), "
               f"MOTA {s['mota']:.3f}, IDF1 {s['idf1']:.3f}, ID switches {s['id_switches']}")
    d = s.get("detectable")
    if d is not None:
        never = d["never_detectable"]
        click.echo(f"over the objects the sensor shows (detectability ≥ 1; {d['undetectable_rows']} rows excused"
                   + (f", never shown: {', '.join(map(str, never))}" if never else "")
                   + f"): HOTA {d['hota']:.3f}, MOTA {d['mota']:.3f}, IDF1 {d['idf1']:.3f}, "
                   f"ID switches {d['id_switches']}")
    click.echo(f"{'object':>6} {'speed px/s':>11} {'found after':>12} {'IoU≥0.5 after':>14} {'error px':>9}")

    def ticks(v):
        return "never" if v is None else f"{v} ticks"

    for oid, o in s["objects"].items():
        err = "—" if o["position_error_px"] is None else f"{o['position_error_px']:.2f}"
        speed = "—" if o["speed_px_per_s"] is None or not np.isfinite(o["speed_px_per_s"]) \
            else f"{o['speed_px_per_s']:.0f}"
        click.echo(f"{oid:>6} {speed:>11} {ticks(o['latency_found_ticks']):>12} "
                   f"{ticks(o['latency_match_ticks']):>14} {err:>9}")
