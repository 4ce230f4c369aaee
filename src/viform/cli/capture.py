"""CLI: ``viform capture SENSOR SCENE`` — shoot a scene with any sensor preset and save what it outputs.

Frame cameras write their frames (.npz or .zarr) with the start time and length of every
exposure window, the unit of the values and the sensor's full description; the spike camera
writes its spike stream (.dat + sidecar, .npz, .zarr). ``--preview`` adds a PNG (one
image) or an MP4/GIF (every frame), tone-mapped on a log scale.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import click
import numpy as np

from viform._validate import ViformError, check_int, check_positive, size_text
from viform.cli._common import CatalogHelp, parse_settings
from viform.cli._scenes import scene_set_option, scene_settings, with_scene_list
from viform.cli.app import cli

#: Frame-file suffixes.
FRAME_FORMATS = (".npz", ".zarr")
PREVIEW_FORMATS = (".png", ".mp4", ".gif")


def capture_sensor_names() -> list[str]:
    """Every name ``viform capture`` accepts: the sensor catalogue's."""
    from viform.sensors.catalog import sensor_names

    return sensor_names()


def default_resolution(sensor_name: str) -> tuple[int, int]:
    """(rows, columns) of a built-in scene shot by ``sensor_name`` when the user gives none: the
    catalogue's ``scene_shape`` (a spike chip's own array, e.g. spikeone 400×250; 400×250 for the
    spike model, as ``simulate``; 128×64 for frame cameras, as ``compare``)."""
    from viform.sensors.catalog import entry

    return entry(sensor_name).scene_shape


def is_spike(name: str) -> bool:
    from viform.sensors.catalog import entry

    return entry(name).family == "spike"


def save_frame_stack(path, frames, start_times_s, exposure_s, units: str, metadata: dict,
                     extra: dict | None = None) -> Path:
    """Write frames with their exposure windows, unit and metadata (.npz or .zarr), atomically.

    ``extra``: more named arrays to store beside the frames (e.g. a camera's processed output).
    """
    extra = {k: np.asarray(v) for k, v in (extra or {}).items()}
    from viform._io import _jsonable, atomic_path

    path = Path(path)
    meta_json = json.dumps(metadata, default=_jsonable)
    starts = np.asarray(start_times_s, dtype=np.float64)
    exposures = np.asarray(exposure_s, dtype=np.float64)
    if path.suffix.lower() == ".npz":
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez_compressed(f, frames=np.asarray(frames), start_times_s=starts, exposure_s=exposures,
                                end_times_s=starts + exposures, units=np.array(units),
                                metadata_json=np.array(meta_json), **extra)
        return path
    from viform._io import import_uninterrupted

    zarr = import_uninterrupted("zarr")

    with atomic_path(path, suffix=".zarr") as tmp:
        tmp.unlink()
        group = zarr.open_group(str(tmp), mode="w")
        arr = np.asarray(frames)
        z = group.create_array("frames", shape=arr.shape, dtype=arr.dtype, chunks=(1, *arr.shape[1:]))
        z[...] = arr
        for name, data in (("start_times_s", starts), ("exposure_s", exposures), ("end_times_s", starts + exposures),
                           *extra.items()):
            a = group.create_array(name, shape=data.shape, dtype=data.dtype)
            a[...] = data
        group.attrs["viform"] = {"format": "viform-frames", "version": 1, "units": units,
                                 "metadata": json.loads(meta_json)}
    return path


def load_frame_stack(path) -> dict:
    """Read a file written by :func:`save_frame_stack` (frames, times, exposures, units, metadata)."""
    path = Path(path)
    if path.suffix.lower() == ".npz":
        with np.load(path) as z:
            return {"frames": z["frames"], "start_times_s": z["start_times_s"], "exposure_s": z["exposure_s"],
                    "units": str(z["units"]), "metadata": json.loads(str(z["metadata_json"]))}
    from viform._io import import_uninterrupted

    zarr = import_uninterrupted("zarr")

    group = zarr.open_group(str(path), mode="r")
    head = group.attrs["viform"]
    return {"frames": group["frames"][...], "start_times_s": group["start_times_s"][...],
            "exposure_s": group["exposure_s"][...], "units": head["units"], "metadata": head["metadata"]}


def _log_tone(images, floor=None):
    """8-bit log tone mapping shared by all frames of a preview (one scale for the clip).

    Black is ``floor`` (default: the 1st percentile of the positive values). Spike counts pass
    half a spike per window as the floor, so that a pixel with a single spike is grey, not black.
    """
    a = np.asarray(images, dtype=np.float64)
    pos = a[a > 0]
    lo = floor if floor is not None else (float(np.percentile(pos, 1)) if pos.size else 1.0)
    hi = max(float(a.max()), lo * 10)
    out = (np.log10(np.clip(a, lo, hi)) - math.log10(lo)) / (math.log10(hi) - math.log10(lo))
    return np.clip(np.rint(out * 255), 0, 255).astype(np.uint8)


def write_preview(path, images, floor=None) -> None:
    """PNG of the middle image, or an MP4/GIF of all (pixels doubled for visibility); ``floor``: :func:`_log_tone`."""
    import imageio.v3 as iio

    from viform._io import atomic_path, save_image

    gray = _log_tone(images, floor)
    if gray.shape[1] < 200:
        gray = np.repeat(np.repeat(gray, 2, axis=1), 2, axis=2)
    suffix = Path(path).suffix.lower()
    if suffix == ".png":
        save_image(path, gray[len(gray) // 2])
        return
    if suffix == ".mp4":
        h, w = gray.shape[1:]
        pad = ((0, 0), (0, (-h) % 16), (0, (-w) % 16))  # codec blocks of 16
        with atomic_path(path) as tmp:
            iio.imwrite(tmp, np.pad(gray, pad), extension=".mp4", fps=10, codec="libx264")
        return
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, gray, extension=".gif", duration=100, loop=0)


#: Most bytes of frames one capture holds in memory (frames are written at the end).
MAX_FRAME_BYTES = 2e9


def check_frame_budget(n_frames: float, height: int, width: int, flag: str = "--duration") -> None:
    """Refuse, before any work, a frame capture that would not fit in memory (8 bytes a pixel while shot)."""
    need = n_frames * height * width * 8
    if need > MAX_FRAME_BYTES:
        raise ViformError(f"{flag}: {n_frames:.4g} frames of {size_text(height, width)} need {need / 1e9:.3g} GB "
                          f"in memory, "
                          f"more than the {MAX_FRAME_BYTES / 1e9:g} GB limit; shorten {flag} or lower the resolution")


#: Mean spikes per pixel a PNG preview of a spike stream counts (its window grows until it does, up to the clip).
PREVIEW_SPIKES_PER_PIXEL = 8


def _spike_preview(path, stream, rate_per_tick: float) -> float:
    """Write the preview of a spike stream; returns its window, seconds (a PNG) or each frame's (a video).

    A PNG counts spikes over a window centred on the clip, long enough for
    :data:`PREVIEW_SPIKES_PER_PIXEL` spikes per pixel on average (the whole clip at most): a
    dim or short clip is not a black picture of sparse single spikes. A video shows 40
    windows across the clip. The log tone map's black is half a spike per window.
    """
    from viform.imaging import accumulation_image

    n_ticks, clock = stream.n_ticks, stream.clock_hz
    duration_s = n_ticks / clock
    if Path(path).suffix.lower() == ".png":
        needed = PREVIEW_SPIKES_PER_PIXEL / rate_per_tick if rate_per_tick > 0 else n_ticks
        window_ticks = int(min(n_ticks, max(1, math.ceil(needed))))
        window = window_ticks / clock
        image = accumulation_image(stream, stream.start_time_s + duration_s / 2, window).spikes_per_s
        write_preview(path, [image], floor=0.5 / window)
        return window
    n = min(40, n_ticks)
    window = max(1.0 / clock, duration_s / n)
    images = [accumulation_image(stream, stream.start_time_s + (k + 1) * duration_s / n - 0.5 / clock,
                                 window).spikes_per_s for k in range(n)]
    write_preview(path, images, floor=0.5 / window)
    return window


def run_capture(sensor_name: str, scene, duration_s: float, out_path, seed: int = 0, preview=None,
                device: str = "cpu", settings: dict | None = None, on_valid=None) -> dict:
    """Shoot ``scene`` with the catalogue's sensor ``sensor_name`` (with ``settings``) and save its
    output (see the module notes); returns a summary.

    Spike streams are simulated block by block straight into the file (bounded memory).
    ``on_valid``, when given, is called once every input has been checked, just before the
    simulation starts (the CLI prints its first-run compile notice there, so that a refused input
    prints its error alone).
    """
    from viform.sensors.catalog import entry
    from viform.stream.sidecar import provenance

    kind = entry(sensor_name)
    sensor = kind.build(height=None, width=None, **(settings or {}))  # at the scene's resolution
    suffix = Path(out_path).suffix.lower()
    if kind.family == "spike":
        from viform.stream.io import FORMATS, open_spikes, save_spikes

        if suffix not in FORMATS:
            raise ViformError(f"--out = {str(out_path)!r}: a spike stream is saved as one of {', '.join(FORMATS)}")
        # .dat and .zarr writers pack each block at once, so the simulator may reuse its buffer
        lazy = sensor.stream(scene, duration_s, seed=seed, progress=True, reuse_buffer=suffix in (".dat", ".zarr"),
                             device=device)
        if suffix == ".dat":  # whole bytes per frame, and room on the disk, before the first tick
            from viform.stream.dat import check_dat_space

            check_dat_space(out_path, lazy.n_ticks, lazy.height, lazy.width)
        if on_valid is not None:
            on_valid()
        save_spikes(out_path, lazy)
        stream = open_spikes(out_path)
        summary = {"file": str(out_path), "sensor": sensor_name, "kind": "spikes", "n_ticks": stream.n_ticks,
                   "height": stream.height, "width": stream.width, "clock_hz": stream.clock_hz,
                   "threshold_electrons": stream.threshold_electrons, **stream.summary(),
                   "device": lazy.metadata["device"]}
        if preview:
            summary["preview_window_s"] = _spike_preview(preview, stream, summary["mean_firing_rate_per_tick"])
        return summary
    if suffix not in FRAME_FORMATS:
        raise ViformError(f"--out = {str(out_path)!r}: frames are saved as one of {', '.join(FRAME_FORMATS)}")
    if kind.family == "gated" and getattr(scene, "active", None) is None:
        raise ViformError(f"SCENE = {scene.name!r} has no range: the gated camera needs a laser-lit scene with "
                          "distances (built-in: night-road-fog)")
    check_frame_budget(max(1.0, duration_s * sensor.frame_rate_hz), scene.height, scene.width)
    if on_valid is not None:
        on_valid()
    meta = {"scene": scene.describe(), "seed": seed, **provenance()}
    extra = {}
    stack = sensor.capture(scene, duration_s, seed=seed)
    frames, starts, exposures = stack.frames_dn, stack.start_times_s, stack.exposure_s
    if kind.family == "highspeed":
        from viform.isp.highspeed_pipeline import HighSpeedConfig, process_frames

        # what leaves the camera: one frame in N over the link, equalized (seed 002 §3.2–3.3)
        result = process_frames(stack, sensor, HighSpeedConfig(seed=seed), scene)
        units = stack.metadata["units"]
        meta["sensor"] = {**result.config, "timing": result.timing, "link": result.plan}
        extra = {"output_frames": result.output_frames, "output_frame_indices": result.transmitted_indices,
                 "auto_exposure_cycles": result.exposure_cycles}
        units += "; output_frames: equalized 8-bit frames sent over the link (indices in output_frame_indices)"
    elif kind.family == "gated":
        units = (f"DN (sum of {sensor.pulses} gated exposures in the vertical register, black "
                 f"{sensor.parameters.pixel.black_offset_dn:g} DN); exposure_s = total gate-open time")
        meta["sensor"] = sensor.describe()
    else:
        p = sensor.parameters
        units = (f"DN ({p.adc_bits}-bit ADC, black offset {p.black_offset_dn:g} DN, "
                 f"K = {p.system_gain_dn_per_e:.4g} DN/e-)")
        meta["sensor"] = sensor.describe()
    save_frame_stack(out_path, frames, starts, exposures, units, meta, extra)
    if preview:
        write_preview(preview, np.asarray(frames, dtype=np.float64))
    return {"file": str(out_path), "sensor": sensor_name, "kind": "frames", "frames": int(len(frames)),
            "height": int(frames.shape[1]), "width": int(frames.shape[2]), "units": units,
            "first_start_s": float(starts[0]), "exposure_s": [float(x) for x in exposures[:8]]}


@cli.command(cls=CatalogHelp)
@click.argument("sensor")
@click.argument("scene")
@click.option("--duration", "duration_s", type=float, required=True, help="Length of the capture, seconds.")
@click.option("--out", "out_path", type=click.Path(), required=True,
              help="Frames: .npz or .zarr. Spike stream: .dat, .npz or .zarr.")
@click.option("--preview", type=click.Path(dir_okay=False), default=None,
              help="Also write a preview: .png (one image) or .mp4/.gif (every frame), log tone-mapped.")
@click.option("--height", type=int, default=None,
              help="Rows of built-in scenes [default: a spike preset's own (spikeone 250, spiketwo 1000; 250 for "
                   "spike, as simulate), 64 for frame sensors].")
@click.option("--width", type=int, default=None,
              help="Columns of built-in scenes [default: a spike preset's own (spikeone 400, spiketwo 1000; 400 "
                   "for spike), 128 for frame sensors].")
@click.option("--seed", type=int, default=0, show_default=True, help="Noise seed.")
@click.option("--max-lux", type=float, default=4.0, show_default=True,
              help="Illuminance on the sensor of full-scale image/video pixels, lux.")
@click.option("--frame-rate-hz", type=float, default=None, help="Frame rate of a video or image folder.")
@click.option("--device", type=click.Choice(["cpu", "cuda", "auto"]), default="cpu", show_default=True,
              help="Spike sensors: where the simulation runs (CPU cores, a CUDA GPU with the same bits, or a GPU "
                   "when one is found). Frame sensors run on the CPU.")
@click.option("--set", "settings", multiple=True, metavar="NAME=VALUE",
              help="Change one parameter of SENSOR by name, e.g. --set parasitic_light_sensitivity=0.01 or "
                   "--set threshold_level=7 (repeatable; viform sensors show SENSOR lists every parameter with "
                   "its unit, default and allowed values).")
@click.option("--force", is_flag=True,
              help="Spike sensors: run a simulation estimated to take more than a minute (refused without it, with "
                   "the estimate), as viform simulate.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of a line of text.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON summary here.")
@scene_set_option
@with_scene_list
def capture(sensor, scene, duration_s, out_path, preview, height, width, seed, max_lux, frame_rate_hz, device,
            settings, force, as_json, json_file, scene_set):
    """Shoot SCENE with SENSOR and save its output with every exposure window.

    SENSOR: {sensors} (viform sensors describes each).
    SCENE: {scenes}
    """
    from viform._io import check_json_file, check_output_folder, write_json
    from viform.light.catalog import load_scene
    from viform.sensors.catalog import entry
    from viform.sensors.spike_cuda import resolve_device
    from viform.stream.io import FORMATS

    kind = entry(sensor, what="SENSOR")
    spike = kind.family == "spike"
    device = resolve_device(device, "--device") if spike else "cpu"
    check_positive("--duration", duration_s)
    default_height, default_width = default_resolution(sensor)
    height = check_int("--height", default_height if height is None else height, 1)
    width = check_int("--width", default_width if width is None else width, 1)
    check_int("--seed", seed, 0)
    suffix = Path(out_path).suffix.lower()
    allowed = FORMATS if spike else FRAME_FORMATS
    if suffix not in allowed:
        what = "a spike stream" if spike else "frames"
        raise ViformError(f"--out = {out_path!r}: {what} must be saved as one of {', '.join(allowed)}")
    if preview and Path(preview).suffix.lower() not in PREVIEW_FORMATS:
        raise ViformError(f"--preview = {preview!r}: the suffix must be one of {', '.join(PREVIEW_FORMATS)}")
    check_output_folder("--out", Path(out_path).resolve().parent)
    if preview:
        check_output_folder("--preview", Path(preview).resolve().parent)
    check_json_file(json_file)
    overrides = parse_settings(kind, settings)  # names, units, ranges and the model's own limits checked
    from viform.cli.compare import announce_preparation
    from viform.report.compare_report import finite_json

    light = load_scene(scene, height, width, max_lux=max_lux, frame_rate_hz=frame_rate_hz,
                       settings=scene_settings(scene_set))
    if spike:  # hours of simulation from a mistyped --duration are refused, as by viform simulate
        from viform.cli._types import check_simulation_work

        clock_hz = kind.build(height=None, width=None, **overrides).parameters.clock_hz
        check_simulation_work(duration_s, clock_hz, light.height * light.width, force, "--set clock_hz =")
    summary = run_capture(sensor, light, duration_s, out_path, seed=seed, preview=preview, device=device,
                          settings=overrides, on_valid=announce_preparation if spike else None)
    if overrides:
        summary["settings"] = overrides
    if preview:
        summary["preview"] = str(preview)
    summary = finite_json(summary)  # null, not a bare NaN: valid JSON
    if json_file:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2, allow_nan=False))
        return
    if summary["kind"] == "spikes":
        click.echo(f"wrote {out_path}: spike stream, {summary['n_ticks']} ticks × {summary['height']}×"
                   f"{summary['width']} at {summary['clock_hz']:g} Hz")
    else:
        frames = f"{summary['frames']} frame{'s' if summary['frames'] != 1 else ''}"
        click.echo(f"wrote {out_path}: {frames} × {size_text(summary['height'], summary['width'])}, "
                   f"exposure {summary['exposure_s'][0] * 1e3:.4g} ms, {summary['units']}")
    if preview:
        window = summary.get("preview_window_s")
        counted = "" if window is None else \
            f" (spikes counted over {window * 1e3:.3g} ms{' per frame' if Path(preview).suffix != '.png' else ''})"
        click.echo(f"preview: {preview}{counted}")
