"""``viform dataset``: turn a folder of video clips into a spike dataset (Spike-Zoo / SpikeCV layout)."""

from __future__ import annotations

import json

import click

from viform._validate import ViformError
from viform.cli._common import CatalogHelp
from viform.cli._scenes import scene_set_option
from viform.cli.app import cli


def _sig(value: float) -> str:
    return f"{value:.4g}"


@cli.command("dataset", cls=CatalogHelp)
@click.argument("src", type=click.Path(file_okay=False), required=False)
@click.option("--scenes", default=None, metavar="NAME[,NAME…]",
              help="Instead of SRC: make clips from built-in scenes with parameters drawn per clip (speeds, "
                   "directions, brightness, texture), with exact truth: flow, depth, object tracks; random-layers: "
                   "natural images cut into objects moving by random affine motions (see --images).")
@click.option("--images", "images_dir", type=click.Path(), default=None, metavar="DIR",
              help="With --scenes random-layers: take its backgrounds and objects from the images (PNG, JPEG, "
                   "TIFF, BMP) in DIR (default: photographs that ship with scikit-image).")
@scene_set_option
@click.option("--clips", "clips_per_scene", type=int, default=None, help="With --scenes: clips of each scene.")
@click.option("--duration", "duration_s", type=float, default=None, help="With --scenes: length of each clip, s.")
@click.option("--truth-every-ticks", type=int, default=40, show_default=True,
              help="With --scenes: one truth frame (image, flow to the next, depth, boxes) every N ticks.")
@click.option("--pairs", is_flag=True,
              help="With --scenes: also write each clip's clean twin (<clip>-clean: same light and seed, "
                   "no photon noise, no fixed-pattern noise) for denoising.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), required=True,
              help="Dataset folder to write (an unfinished one made with the same options is resumed).")
@click.option("--preset", default=None,
              help="Spike camera: {sensors:spike} (default spikeone), or a preset .json file (viform calibrate).")
@click.option("--set", "sensor_settings", multiple=True, metavar="NAME=VALUE",
              help="Change one parameter of the spike camera by name, e.g. --set threshold_level=7 (repeatable; "
                   "viform sensors show spikeone lists them).")
@click.option("--height", type=int, default=None, help="Sensor rows (default: the preset's).")
@click.option("--width", type=int, default=None, help="Sensor columns (default: the preset's).")
@click.option("--workers", type=int, default=None,
              help="Local worker processes, one clip each at a time (default: the number of CPU cores).")
@click.option("--scheduler", default=None, help="Address of a running dask scheduler (tcp://HOST:PORT) "
              "to use instead of local workers.")
@click.option("--connect-timeout", "connect_timeout_s", type=float, default=20.0, show_default=True,
              help="Seconds to keep trying to reach --scheduler, at the start and after losing it; then the run "
                   "stops with one line saying what is done (running the command again resumes).")
@click.option("--worker-memory", default="auto", show_default=True,
              help="Memory limit of each local worker, e.g. 2GiB (auto: the machine's memory shared evenly).")
@click.option("--gt-every", type=int, default=1, show_default=True,
              help="Write a ground-truth image for every N-th source frame.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Dataset seed; each clip's photon-noise seed is derived from it and the clip's name.")
@click.option("--frame-rate-hz", type=float, default=None,
              help="Frame rate of the source clips (required for folders of images; videos declare their own).")
@click.option("--max-lux", type=float, default=None,
              help="Illuminance of a full-scale source pixel, lux (default: the light at which the sensor "
                   "fires 0.6 spikes per tick).")
@click.option("--interpolation", type=click.Choice(["hold", "linear"]), default="linear", show_default=True,
              help="Light between source frames.")
@click.option("--light-sample-ticks", type=int, default=1, show_default=True,
              help="Evaluate the light once every N ticks (1: every tick).")
@click.option("--block-ticks", type=int, default=4096, show_default=True,
              help="Ticks simulated and written at a time (bounds each worker's memory; same bits).")
@click.option("--device", type=click.Choice(["cpu", "cuda", "auto"]), default="cpu", show_default=True,
              help="Where the spike simulation runs: CPU cores, a CUDA GPU (pip install \"viform[cuda]\"; "
                   "the same bits), or a GPU when one is found.")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON summary here.")
def dataset(src, scenes, images_dir, scene_set, clips_per_scene, duration_s, truth_every_ticks, pairs, out_dir,
            preset, height, width, workers, scheduler, connect_timeout_s, worker_memory, gt_every, seed, frame_rate_hz,
            max_lux, interpolation, light_sample_ticks, block_ticks, device, no_progress, as_json, json_file,
            sensor_settings):
    """Convert SRC, a folder of videos or of frame folders, into a spike dataset in --out;
    or, with --scenes, make one from built-in scenes or random layered scenes with exact truth.

    Writes spike/<clip>.dat (the spike cameras' packed-bit layout) with a JSON description
    beside each, gt/<clip>_<frame>.png ground truth, config.yaml (spike_h, spike_w) and
    manifest.json (ticks, spikes and SHA-256 of every clip). Scene clips add flow/<clip>_<k>.flo
    (forward flow to the next truth frame, px), depth/<clip>_<k>.npy (m, scenes with range) and
    mot/<clip>/gt/gt.txt + seqinfo.ini (MOTChallenge object tracks). Clips run in parallel on local
    worker processes or on a dask cluster; finished clips are checked and skipped when the
    command is run again. Exit status 1 when a clip failed (the others are still written).
    """
    from viform._io import check_json_file, write_json
    from viform.cli._common import announce_connection
    from viform.datasets.build import build_dataset, make_settings, scene_clips
    from viform.sensors.spike_cuda import resolve_device

    check_json_file(json_file)
    device = resolve_device(device, "--device")
    if (src is None) == (scenes is None):
        raise ViformError("give either SRC (a folder of videos or frame folders) or --scenes NAME[,NAME…], "
                          "not " + ("both" if src is not None else "neither"))
    if scenes is None:
        for flag, value in (("--clips", clips_per_scene), ("--duration", duration_s)):
            if value is not None:
                raise ViformError(f"{flag} applies to --scenes datasets only; SRC's clips keep their own length")
        if pairs:
            raise ViformError("--pairs applies to --scenes datasets only")
        if images_dir is not None:
            raise ViformError("--images applies to --scenes random-layers only")
        if scene_set is not None:
            raise ViformError("--scene-set applies to --scenes datasets only (SRC's clips are videos and images)")
    else:
        for flag, value in (("--clips", clips_per_scene), ("--duration", duration_s)):
            if value is None:
                raise ViformError(f"--scenes needs {flag}")
    from viform.cli._common import parse_settings
    from viform.sensors.catalog import SENSORS

    camera = SENSORS.get(preset or "spikeone")
    overrides = parse_settings(camera if camera is not None and camera.family == "spike" else SENSORS["spike"],
                               sensor_settings, skip_build=True)
    settings = make_settings(preset, height=height, width=width, seed=seed, gt_every=gt_every,
                             frame_rate_hz=frame_rate_hz, max_lux=max_lux, interpolation=interpolation,
                             light_sample_ticks=light_sample_ticks,
                             truth_every_ticks=truth_every_ticks if scenes is not None else None, **overrides)
    _check_max_lux(settings)
    if scenes is not None:
        from viform.cli._scenes import scene_settings

        src = scene_clips(scenes, clips_per_scene, duration_s, settings, pairs, images=images_dir,
                          scene_settings=scene_settings(scene_set))
    summary = build_dataset(src, out_dir, settings, workers=workers, scheduler=scheduler,
                            memory_limit=worker_memory, block_ticks=block_ticks, progress=not no_progress,
                            device=device, connect_timeout_s=connect_timeout_s, on_connect=announce_connection)
    if json_file is not None:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        rows = [
            ("dataset", summary["out"]),
            ("sensor", f"{settings.width}×{settings.height} px, {_sig(settings.parameters.clock_hz / 1e3)} kHz, "
                       f"Q = {_sig(settings.parameters.threshold_electrons)} e-, full scale {_sig(settings.max_lux)} "
                       f"lux"),
            ("preset", settings.preset + ("" if preset is not None else " (the dataset default; give --preset to "
                                          "change it — viform simulate's default is Q = 100 e-)")),
            ("clips", f"{summary['clips']} (converted {summary['converted']}, skipped {summary['skipped']} "
                      f"already done, failed {len(summary['failed'])}"
                      + (f": {', '.join(f['clip'] for f in summary['failed'])}" if summary["failed"] else "") + ")"),
            *(("frames", fit) for fit in summary.get("fits", [])),
            ("ticks", f"{summary['ticks']:,}"),
            ("spikes", f"{summary['spikes']:,}"),
            ("spike data", f"{_sig(summary['bytes'] / 1e6)} MB"),
            ("time", f"{_sig(summary['seconds'])} s on {summary['workers']} "
                     f"worker{'' if summary['workers'] == 1 else 's'}"),
            ("speed", f"{_sig(summary['clips_per_s'])} clips/s, {_sig(summary['pixel_ticks_per_s'])} pixel-ticks/s"),
        ]
        dark = summary.get("too_dark", [])
        if dark:
            rows.append(("too dark", f"{len(dark)} clip{'s' if len(dark) > 1 else ''} fire less than once a pixel "
                                     f"per truth step at this preset ({', '.join(dark[:6])}"
                                     + (", …" if len(dark) > 6 else "") + "): flagged too_dark in the manifest"))
        for name, value in rows:
            click.echo(f"{name:<12} {value}")
    for fail in summary["failed"]:
        click.echo(f"viform: clip {fail['clip']!r} failed: {fail['error']}", err=True)
    if summary["failed"]:
        raise ClipsFailed(f"{len(summary['failed'])} of {summary['clips']} clips failed (listed above); "
                          "the others are written, and running the command again retries only the failed ones")


def _check_max_lux(settings) -> None:
    """A full-scale pixel brighter than the simulator can represent would fail every clip on its
    worker: refuse --max-lux here, before any work, with the line ``simulate`` prints."""
    import numpy as np

    from viform._validate import ViformError
    from viform.sensors.spike import SpikeSensor

    try:
        SpikeSensor(settings.parameters, 1, 1)._fixed_point_rates(np.array([[settings.max_lux]]), 1, 1)
    except ViformError as exc:
        raise ViformError(f"--max-lux = {settings.max_lux:g}: {exc}") from None


class ClipsFailed(click.ClickException):
    """Some clips failed: exit status 1 (bad options exit 2)."""

    exit_code = 1
