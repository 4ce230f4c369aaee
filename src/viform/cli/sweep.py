"""CLI: ``viform sweep SCENE`` — a sensor at many settings on one scene: the trade-off, the setting meeting demands."""

from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path

import click

from viform._io import JSON_FILE_HELP
from viform._validate import ViformError
from viform.cli._common import CatalogHelp
from viform.cli._scenes import built_in_scene_options, scene_options, scene_set_option, with_scene_list
from viform.cli.app import cli

#: Largest --speed factor of the dilemma scene a sweep accepts.
MAX_SPEED = 100.0
#: The library's parameter names (:func:`viform.measure.sweep.make_plan`, :func:`~viform.measure.sweep.sweep`,
#: their helpers) → this command's flags: an error about a parameter names the flag the user typed
#: (the one place the command's flags meet the library's names; see ``cli._types.flag_message``).
SWEEP_FLAGS = {
    "scene": "SCENE", "sensors": "--sensor", "key": "--sensor", "vary_texts": "--vary", "vary": "--vary",
    "settings": "--vary", "require": "--require", "objective": "--objective", "spike_image": "--spike-image",
    "duration_s": "--duration", "instants_s": "--at", "height": "--height", "width": "--width", "seed": "--seed",
    "out": "--out", "workers": "--workers", "scheduler": "--scheduler", "memory_limit": "--worker-memory",
    "connect_timeout_s": "--connect-timeout",
    "tracking": "--tracking", "scene_options": "--scene-set", "device": "--device",
}


@cli.command("sweep", cls=CatalogHelp)
@click.argument("scene")
@click.option("--sensor", "sensors", multiple=True,
              help="A sensor to sweep (repeat for several): any of {sensors}. Default: the standard sweep "
                   "(spikeone's 16 threshold levels × 20/40 kHz, 20 settings of each frame sensor).")
@click.option("--vary", "vary", multiple=True, metavar="[SENSOR:]PARAM=SPEC",
              help="Values of one parameter (repeat for a grid): a,b,c | start:stop:step | log:start:stop:n "
                   "(threshold_level=all: the 16 chip levels). Without SENSOR: every swept sensor that has PARAM. "
                   "scene:PARAM=SPEC varies a parameter of the scene (e.g. scene:brightness=0.1,1,10, "
                   "scene:speed=0.5,1,2): every sensor's points are shot at each value, and each gets its own "
                   "answer. viform sensors show SENSOR lists a sensor's parameters with units and allowed values; "
                   "--list-parameters shows each sensor's and the scene's parameters.")
@click.option("--require", default=None, metavar="DEMANDS",
              help="Demands every point is checked against, e.g. \"dr_captured_db>=120,edge_width_px<=2,"
                   "data_rate_mb_per_s<=50\" (metric names of compare's metrics.json).")
@click.option("--objective", default="psnr_log_db", show_default=True,
              help="Metric that picks the best point per sensor among those meeting the demands.")
@click.option("--spike-image", default="best", show_default=True,
              help="Spike reconstruction scored: best (the best method of the imaging package), interval, "
                   "accumulation.")
@click.option("--duration", "duration_s", type=float, default=0.04, show_default=True, help="Clip length, s.")
@click.option("--at", "at", default=None, help="Instants to score, s, comma-separated (default: 30/50/70 %).")
@built_in_scene_options
@click.option("--seed", type=int, default=0, show_default=True,
              help="Sweep seed; each point's noise seed is derived from it and the point.")
@click.option("--out", "out_dir", type=click.Path(), default="viform-sweep", show_default=True,
              help="Output folder (report.html, sweep.zarr, sweep.json, points/). A folder holding a sweep of the "
                   "same scene and options is resumed or extended: stored points are reused.")
@click.option("--workers", type=int, default=None,
              help="Local dask worker processes (default: the number of CPU cores); 0: in this process, no dask.")
@click.option("--scheduler", default=None, help="Address of a running dask scheduler (tcp://HOST:PORT) "
              "to use instead of local workers.")
@click.option("--connect-timeout", "connect_timeout_s", type=float, default=20.0, show_default=True,
              help="Seconds to keep trying to reach --scheduler, at the start and after losing it; then the run "
                   "stops with one line saying what is done (running the command again resumes).")
@click.option("--worker-memory", default="auto", show_default=True,
              help="Memory limit of each local worker, e.g. 2GiB (auto: the machine's memory shared evenly).")
@click.option("--tracking", is_flag=True,
              help="Also track the scene's objects at every point and score it against the truth (HOTA, MOTA, IDF1, "
                   "ID switches, latency; scenes with object truth). Slower.")
@click.option("--device", type=click.Choice(["cpu", "cuda", "auto"]), default="cpu", show_default=True,
              help="Where the spike sensor's simulations run: CPU cores, a CUDA GPU (pip install \"viform[cuda]\"; "
                   "the same bits for the same seed), or a GPU when one is found.")
@click.option("--list-parameters", is_flag=True,
              help="List each sensor's parameters and the scene's (scene:PARAM) with their defaults, and exit.")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help=JSON_FILE_HELP)
@scene_set_option
@with_scene_list
def sweep(scene, sensors, vary, require, objective, spike_image, duration_s, at, height, width, brightness, speed,
          visibility_m, seed, out_dir, workers, scheduler, connect_timeout_s, worker_memory, tracking, device,
          list_parameters, no_progress, as_json, json_file, scene_set):
    """Shoot SCENE with each --sensor at every setting --vary gives; score each point as `viform compare`
    does; write OUT/report.html (trade-offs, Pareto fronts, best images) and OUT/sweep.zarr.

    SCENE: {scenes}

    With --require, names the setting of each sensor that meets every demand (best by --objective)
    or, where none does, the nearest miss and by how much.
    """
    from viform.cli.compare import command_start

    started = command_start()
    from viform._io import check_json_file, write_json
    from viform.measure import sweep as sw
    from viform.measure.comparison import compare_entry

    if list_parameters:
        keys = list(sensors) or list(sw.SWEEP_SENSORS)
        doc = {k: {n: p.default for n, p in sw.sweep_parameters(k).items()} for k in keys}
        doc["scene"] = {n: p.default for n, p in sw.scene_parameters(scene).items()}
        if as_json:
            click.echo(json.dumps(doc, indent=2, default=str))
        else:
            for k in keys:
                click.echo(f"{k}: " + ", ".join(f"{n}={p!r}" for n, p in sorted(doc[k].items())))
            click.echo(f"scene ({scene}; vary as scene:PARAM): "
                       + (", ".join(f"{n}={p!r}" for n, p in doc["scene"].items()) or "no parameters"))
        return
    from viform.cli.compare import announce_preparation, check_outputs, parse_instants
    from viform.report.sweep_report import console_lines, run_sweep_report

    if workers is not None and scheduler is not None:
        raise ViformError("--workers and --scheduler exclude each other: a scheduler brings its own workers")
    instants = parse_instants(at)
    options = {k: v for k, v in (("brightness", brightness), ("speed", speed), ("visibility_m", visibility_m))
               if v is not None}
    for name, scenes in (("brightness", ("dilemma", "night-road-fog")), ("speed", ("dilemma",)),
                         ("visibility_m", ("night-road-fog",))):
        if name in options and scene not in scenes:
            raise ViformError(f"--{name.replace('_', '-')} applies to the {' and '.join(scenes)} scene"
                              f"{'s' if len(scenes) > 1 else ''} only, not to SCENE = {scene!r}")
    if speed is not None and speed > MAX_SPEED:  # the scene samples its window means every 0.5 px of motion
        raise ViformError(f"--speed {speed:g} is not allowed: at most {MAX_SPEED:g} (× the scene's 2 000–3 000 px/s)")
    options.update({k: tuple(v) if isinstance(v, list) else v for k, v in scene_options(scene, scene_set).items()})
    plan = sw.make_plan(scene, list(sensors) or None, list(vary), height=height, width=width, duration_s=duration_s,
                        seed=seed, instants_s=instants, require=require, objective=objective,
                        spike_image=spike_image, scene_options=options, tracking=tracking)
    check_outputs(out_dir, json_file)
    check_json_file(json_file)
    try:  # before the compile notice: an error is the only line
        sw.check_device(device, plan.sensors)
        sw.check_context(Path(out_dir), plan.context)
        if any(compare_entry(k).family == "spike" for k in plan.sensors):
            announce_preparation()
        from viform.cli._common import announce_connection

        doc = run_sweep_report(plan, out_dir, workers=workers, scheduler=scheduler, memory_limit=worker_memory,
                               progress=not no_progress, device=device, connect_timeout_s=connect_timeout_s,
                               on_connect=announce_connection,
                               command=shlex.join(["viform", *sys.argv[1:]]) if sys.argv else "", started_s=started)
    except sw.ContextMismatch as exc:
        what = SWEEP_FLAGS.get(exc.field, exc.field)
        raise ViformError(f"--out {exc.out!r} holds a sweep made with other options ({what}: {exc.stored!r} there, "
                          f"{exc.wanted!r} now); give a new --out, or the same options to extend or resume it"
                          ) from None
    summary = {"report": doc["report"], "table": str(Path(out_dir) / "sweep.zarr"),
               "sweep": str(Path(out_dir) / "sweep.json"), "n_points": doc["n_points"], "computed": doc["computed"],
               "reused": doc["reused"], "seconds": doc["seconds"], "cpu_seconds": doc["cpu_seconds"],
               "wall_s": time.perf_counter() - started, "workers": doc["workers"],
               "answer": {k: v for k, v in doc["answer"].items() if k != "meeting"}}
    summary = sw._finite(summary)
    if json_file:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2, allow_nan=False))
        return
    for line in console_lines(doc):
        click.echo(line)
    sparse = [r for r in doc.get("records", []) if r.get("warning")]
    if sparse:
        click.echo(f"warning: {len(sparse)} of {len(doc['records'])} points are scored on too few spikes; "
                   f"{sparse[0]['label']}: {sparse[0]['warning'].removeprefix('warning: ')}", err=True)
    click.echo(f"\nwrote {summary['report']} and {summary['table']} in {summary['wall_s']:.1f} s")


sweep.viform_flags = SWEEP_FLAGS
