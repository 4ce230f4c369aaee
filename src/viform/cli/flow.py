"""CLI: ``viform flow`` — optical flow from a spike stream, scored against the scene's exact truth."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from viform._io import JSON_FILE_HELP
from viform._validate import ViformError
from viform.cli.app import cli


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


@cli.command("flow")
@click.argument("file", type=click.Path(exists=True))
@click.option("--at", "at_s", type=float, required=True, help="First instant, s.")
@click.option("--dt", "dt_s", type=float, default=1e-3, show_default=True,
              help="Flow interval, s: the flow is the motion from --at to --at + --dt.")
@click.option("--method", type=click.Choice(["multi-interval", "interval", "accumulation"]), default="multi-interval",
              show_default=True, help="How the light at each instant is imaged from the spikes.")
@click.option("--preset", type=click.Choice(["ultrafast", "fast", "medium"]), default="fast", show_default=True,
              help="Speed against accuracy of the flow matcher (OpenCV DIS); fast was the most accurate on spikes.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="viform-flow", show_default=True,
              help="Folder for flow.npy (2×H×W, px), flow.flo (Middlebury), flow.png and metrics.json.")
@click.option("--score", is_flag=True,
              help="Require the scene's truth and score against it (without it: scored when the file has truth).")
@click.option("--height", type=int, default=None, help=".dat files without a sidecar: rows.")
@click.option("--width", type=int, default=None, help=".dat files without a sidecar: columns.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help=JSON_FILE_HELP)
def flow(file, at_s, dt_s, method, preset, out_dir, score, height, width, as_json, json_file):
    """Optical flow of FILE (any spike file viform reads) from --at to --at + --dt.

    Writes the flow field (px, forward: where each pixel's surface point went) as flow.npy and
    flow.flo, and a colour-wheel picture. When FILE was simulated by viform from a built-in
    scene, its exact flow is known: the average endpoint error (EPE, px) and the share of
    outliers (Fl: EPE > 3 px and > 5 % of the true motion) are printed, overall, on textured
    pixels, and per object.
    """
    import numpy as np

    from viform._io import atomic_path, check_json_file, check_output_folder, write_json
    from viform.cli._common import open_source
    from viform.vision.flow import check_interval, estimate_flow, flow_figure, flow_scores, textured_mask, write_flo

    check_output_folder("--out", Path(out_dir))
    check_json_file(json_file)
    source = open_source(file, height, width)
    check_interval(source, at_s, dt_s)
    scene = truth_scene_of(source, "--score" if score else None)
    estimate = estimate_flow(source, at_s, dt_s, method=method, preset=preset)
    summary = {"file": str(file), "t0_s": estimate.t0_s, "t1_s": estimate.t1_s, "method": method, "preset": preset,
               "height": source.height, "width": source.width, "truth": scene is not None}
    truth = None
    if scene is not None:
        truth = scene.optical_flow_px(estimate.t0_s, estimate.t1_s)
        margin = int(math.ceil(float(np.nanmax(np.abs(truth.flow_px))))) + 4
        textured = textured_mask(scene.illuminance_lux(estimate.t0_s), margin_px=margin)
        summary["scores"] = {"all": flow_scores(estimate.flow_px, truth).as_dict(),
                             "textured": flow_scores(estimate.flow_px, truth, textured).as_dict()}
        if "objects" in scene.truth_kinds():
            labels = scene.object_labels(estimate.t0_s)
            summary["scores"]["objects"] = {
                f"{o.object_id} {o.class_name}": flow_scores(estimate.flow_px, truth, labels == o.object_id).as_dict()
                for o in scene.objects(estimate.t0_s) if (labels == o.object_id).any()}
    with atomic_path(out_dir, directory=True) as folder:
        folder = Path(folder)
        folder.mkdir()
        np.save(folder / "flow.npy", estimate.flow_px)
        write_flo(folder / "flow.flo", estimate.flow_px)
        title = (f"optical flow {estimate.t0_s * 1e3:.4g} → {estimate.t1_s * 1e3:.4g} ms "
                 f"({method} images, DIS {preset})")
        scored = flow_scores(estimate.flow_px, truth) if truth is not None else None
        flow_figure(folder / "flow.png", estimate.flow_px, truth=truth, title=title, scores=scored)
        write_json(folder / "metrics.json", summary)
    if json_file is not None:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"flow {summary['t0_s'] * 1e3:.5g} → {summary['t1_s'] * 1e3:.5g} ms of {file} "
               f"({source.width}×{source.height} px), {method} images, DIS {preset}: written to {out_dir}/")
    if scene is None:
        click.echo("truth: none (the file was not simulated from a built-in scene), so no error is computed")
        return
    click.echo(f"{'pixels':<28} {'EPE px':>8} {'Fl %':>7} {'true flow px':>13} {'scored':>8}")
    rows = [("all with valid truth", summary["scores"]["all"]), ("textured", summary["scores"]["textured"])]
    rows += [(name, s) for name, s in summary["scores"].get("objects", {}).items()]
    for name, s in rows:
        if s["pixels"]:
            click.echo(f"{name:<28} {s['epe_px']:>8.3f} {100 * s['fl_outliers']:>7.2f} {s['true_flow_px']:>13.3g} "
                       f"{s['pixels']:>8,}")
        else:
            click.echo(f"{name:<28} {'—':>8} {'—':>7} {'—':>13} {0:>8}")
