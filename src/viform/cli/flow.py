"""CLI: ``viform flow`` — optical flow from a spike stream, scored against the scene's exact truth."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from viform._io import JSON_FILE_HELP
from viform._validate import ViformError, size_text
from viform.cli.app import cli

#: Verdicts on a motion by its error relative to the true motion (EPE / true length).
MEASURED_BELOW, ROUGH_BELOW = 0.2, 0.5


def truth_scene_of(source, flag: str | None = None):
    """The built-in scene a stream was simulated from (its truth), or None; with ``flag``, refuse instead of None."""
    from viform.light.catalog import scene_from_description
    from viform.light.truth import TruthUnavailable

    try:
        return scene_from_description((source.metadata or {}).get("scene"))
    except TruthUnavailable as exc:
        if flag is None:
            return None
        raise ViformError(f"{flag}: {exc}") from None


def verdict(relative_error: float) -> str:
    """'measured' (error ≤ 20 % of the motion), 'rough' (≤ 50 %) or 'missed'; '—' when undefined."""
    if relative_error is None or not math.isfinite(relative_error):
        return "—"
    return "measured" if relative_error <= MEASURED_BELOW else "rough" if relative_error <= ROUGH_BELOW else "missed"


def _finite(value):
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _clean(doc):
    if isinstance(doc, dict):
        return {k: _clean(v) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_clean(v) for v in doc]
    return _finite(doc)


@cli.command("flow")
@click.argument("file", type=click.Path(exists=True))
@click.option("--at", "at_s", type=float, required=True, help="First instant, s.")
@click.option("--dt", "dt_s", type=float, default=1e-3, show_default=True,
              help="Flow interval, s: the flow is the motion from --at to --at + --dt.")
@click.option("--method", type=click.Choice(["multi-interval", "interval", "accumulation"]), default="multi-interval",
              show_default=True, help="How the light at each instant is imaged from the spikes.")
@click.option("--preset", type=click.Choice(["ultrafast", "fast", "medium"]), default="fast", show_default=True,
              help="Speed against accuracy of the dense flow (OpenCV DIS).")
@click.option("--refine", type=click.Choice(["layered", "none"]), default="layered", show_default=True,
              help="layered: regions that move as a whole (a uniform or saturated object) get one motion, found "
                   "over the still background, which gets zero flow; none: the dense flow alone.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="viform-flow", show_default=True,
              help="Folder for flow.npy (2×H×W, px), confidence.npy, flow.flo (Middlebury), flow.png and "
                   "metrics.json.")
@click.option("--score", is_flag=True,
              help="Require the scene's truth and score against it (without it: scored when the file has truth).")
@click.option("--height", type=int, default=None, help=".dat files without a sidecar: rows.")
@click.option("--width", type=int, default=None, help=".dat files without a sidecar: columns.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help=JSON_FILE_HELP)
def flow(file, at_s, dt_s, method, preset, refine, out_dir, score, height, width, as_json, json_file):
    """Optical flow of FILE (any spike file viform reads) from --at to --at + --dt.

    Writes the flow field (px, forward: where each pixel's surface point went) as flow.npy and
    flow.flo, a confidence per pixel (0–1: how well the spikes resolve the interval there) and
    a colour-wheel picture. When FILE was simulated by viform from a built-in scene, its exact
    flow is known, and the scores put first what moves: the average endpoint error (EPE, px)
    over the pixels whose true motion exceeds 0.5 px, as a share of that motion (100 % is no
    better than reading zero flow), then each object, then the still background's false
    motion apart. Every figure is printed beside what zero flow would score.
    """
    import numpy as np

    from viform._io import atomic_path, check_json_file, check_output_folder, write_json
    from viform.cli._common import open_source
    from viform.imaging.support import spike_support
    from viform.vision.flow import check_interval, estimate_flow, flow_figure, motion_scores, write_flo

    check_output_folder("--out", Path(out_dir))
    check_json_file(json_file)
    source = open_source(file, height, width)
    tick0, tick1 = check_interval(source, at_s, dt_s, names=("--at", "--dt"))
    scene = truth_scene_of(source, "--score" if score else None)
    # a pixel needs one interval (2 spikes) within --dt, else its images at both instants are made of
    # the same spikes and cannot show a change
    span = tick1 - tick0
    support = spike_support(source, span, 2, tick0 - span, tick1 + span + 1)
    warning = support.warning(f"{method} flow over --dt {dt_s:g} s",
                              "brighten the scene or lower the threshold Q (simulate -q / --threshold-level), or "
                              "give a longer --dt")
    if warning:
        click.echo(warning, err=True)
    estimate = estimate_flow(source, at_s, dt_s, method=method, preset=preset, refine=refine)
    summary = {"file": str(file), "t0_s": estimate.t0_s, "t1_s": estimate.t1_s, "method": method, "preset": preset,
               "refine": refine, "height": source.height, "width": source.width, "truth": scene is not None,
               "support": support.as_dict(), "warning": warning,
               "moving_regions": len(estimate.info.get("regions", [])),
               "mean_confidence": float(np.mean(estimate.confidence))}
    truth = scores = None
    if scene is not None:
        truth = scene.optical_flow_px(estimate.t0_s, estimate.t1_s)
        labels = names = None
        if "objects" in scene.truth_kinds():
            labels = scene.object_labels(estimate.t0_s)
            names = {o.object_id: o.class_name for o in scene.objects(estimate.t0_s)}
        scores = motion_scores(estimate.flow_px, truth, labels, names)
        zero = motion_scores(np.zeros_like(estimate.flow_px), truth, labels, names)
        summary["scores"] = {**scores.as_dict(), "zero_flow": zero.as_dict()}
    summary = _clean(summary)
    with atomic_path(out_dir, directory=True) as folder:
        folder = Path(folder)
        folder.mkdir()
        np.save(folder / "flow.npy", estimate.flow_px)
        np.save(folder / "confidence.npy", estimate.confidence)
        write_flo(folder / "flow.flo", estimate.flow_px)
        title = (f"optical flow {estimate.t0_s * 1e3:.4g} → {estimate.t1_s * 1e3:.4g} ms "
                 f"({method} images, DIS {preset}, refine {refine})")
        flow_figure(folder / "flow.png", estimate.flow_px, truth=truth, title=title, scores=scores)
        write_json(folder / "metrics.json", summary)
    if json_file is not None:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"flow {summary['t0_s'] * 1e3:.5g} → {summary['t1_s'] * 1e3:.5g} ms of {file} "
               f"({size_text(source.height, source.width)}), {method} images, DIS {preset}, refine {refine}: "
               f"written to {out_dir}/")
    click.echo(f"moving regions found: {summary['moving_regions']}; mean confidence {summary['mean_confidence']:.2f}")
    if scene is None:
        click.echo("truth: none (the file was not simulated from a built-in scene), so no error is computed")
        return
    s, z = summary["scores"], summary["scores"]["zero_flow"]
    mv = s["moving"]
    if mv["pixels"]:
        click.echo(f"moving pixels (true motion > {s['moving_above_px']:g} px, {mv['pixels']:,} px, mean "
                   f"{mv['true_flow_px']:.3g} px): EPE {mv['epe_px']:.3f} px = {100 * mv['relative_error']:.0f} % of "
                   f"the motion — {verdict(mv['relative_error'])} (zero flow: {z['moving']['epe_px']:.3f} px = 100 %)")
    else:
        click.echo("moving pixels: none (nothing moves more than "
                   f"{s['moving_above_px']:g} px between the two instants)")
    st = s["still"]
    if st["pixels"]:
        click.echo(f"still background ({st['pixels']:,} px): median false motion "
                   f"{st['median_false_motion_px']:.3f} px, 95th percentile {st['p95_false_motion_px']:.3f} px "
                   "(zero flow: 0)")
    else:
        click.echo("still background: none (every pixel with valid truth moves, as under a moving camera)")
    if s["objects"]:
        click.echo(f"{'object':<20} {'true px':>8} {'EPE px':>8} {'of motion':>10} {'verdict':>9} {'zero flow':>10} "
                   f"{'scored':>7}")
        for name, o in s["objects"].items():
            if not o["pixels"]:
                continue
            rel = o["relative_error"]
            share = f"{100 * rel:.0f} %" if rel is not None else "—"
            click.echo(f"{name:<20} {o['true_flow_px']:>8.3g} {o['epe_px']:>8.3f} {share:>10} {verdict(rel):>9} "
                       f"{z['objects'][name]['epe_px']:>10.3f} {o['pixels']:>7,}")
    a = s["all"]
    click.echo(f"all pixels with valid truth ({a['pixels']:,} px): EPE {a['epe_px']:.3f} px, Fl "
               f"{100 * a['fl_outliers']:.2f} % (zero flow: EPE {z['all']['epe_px']:.3f} px)")
