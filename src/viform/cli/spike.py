"""CLI commands of the spike camera core: simulate, reconstruct, info, demo (seed 000)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click
import numpy as np

from viform._validate import ViformError
from viform.cli.app import cli


def _parse_times(text: str) -> list[float]:
    try:
        times = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise ViformError(f"--at = {text!r} is not allowed: give instants in seconds, e.g. --at 0.01,0.02") from None
    if not times:
        raise ViformError("--at is empty: give at least one instant in seconds")
    return times


def _sensor_from_options(clock_hz, threshold_electrons, dark_current_e_per_s, quantum_efficiency, pixel_pitch_um,
                         fill_factor, threshold_spread, reset, no_noise, no_random_initial):
    from viform.light.radiometry import PixelOptics
    from viform.sensors.spike import SpikeSensor, SpikeSensorParameters

    optics = PixelOptics(pixel_pitch_m=pixel_pitch_um * 1e-6, fill_factor=fill_factor,
                         quantum_efficiency=quantum_efficiency)
    params = SpikeSensorParameters(optics=optics, threshold_electrons=threshold_electrons, clock_hz=clock_hz,
                                   dark_current_e_per_s=dark_current_e_per_s,
                                   threshold_spread_fraction=threshold_spread, reset=reset,
                                   photon_noise=not no_noise, random_initial_charge=not no_random_initial)
    return SpikeSensor(params)


def _open(path, height, width, clock_hz=None, flip=True, allow_partial=False):
    from viform.stream.io import open_spikes

    return open_spikes(path, height, width, clock_hz=clock_hz, flip=flip, allow_partial=allow_partial)


sensor_options = [
    click.option("--clock-hz", type=float, default=40_000.0, show_default=True,
                 help="Readout clock, Hz (the chip: 40 kHz, or 20 kHz mode)."),
    click.option("--threshold-electrons", "-q", type=float, default=100.0, show_default=True,
                 help="Accumulation threshold Q, electrons."),
    click.option("--dark-current-e-per-s", type=float, default=20.0, show_default=True, help="Dark current, e-/s."),
    click.option("--quantum-efficiency", type=float, default=0.7, show_default=True),
    click.option("--pixel-pitch-um", type=float, default=10.0, show_default=True, help="Pixel pitch, µm."),
    click.option("--fill-factor", type=float, default=1.0, show_default=True),
    click.option("--threshold-spread", type=float, default=0.0, show_default=True,
                 help="Fixed-pattern spread of Q across pixels (std/mean)."),
    click.option("--reset", type=click.Choice(["self", "readout"]), default="self", show_default=True,
                 help="Self-reset at the threshold, or reset at the next readout tick."),
    click.option("--no-noise", is_flag=True, help="Deterministic model: no photon noise."),
    click.option("--no-random-initial", is_flag=True, help="Start every pixel with an empty well."),
]


def _apply(options):
    def decorator(f):
        for option in reversed(options):
            f = option(f)
        return f

    return decorator


@cli.command()
@click.argument("scene")
@click.option("--duration", "duration_s", type=float, required=True, help="Length of the stream, seconds.")
@click.option("--out", "out_path", type=click.Path(dir_okay=True), required=True,
              help="Output file: .dat (spike-camera layout), .zarr (chunked, with metadata) or .npz.")
@click.option("--seed", type=int, default=0, show_default=True, help="Photon-noise seed.")
@click.option("--height", type=int, default=250, show_default=True, help="Resolution of built-in scenes.")
@click.option("--width", type=int, default=400, show_default=True)
@click.option("--max-lux", type=float, default=4.0, show_default=True,
              help="Illuminance on the sensor of full-scale image/video pixels, lux.")
@click.option("--frame-rate-hz", type=float, default=None, help="Frame rate of a video or image folder.")
@click.option("--interpolation", type=click.Choice(["hold", "linear"]), default="linear", show_default=True,
              help="Light between video frames.")
@click.option("--light-sample-ticks", type=int, default=1, show_default=True,
              help="Evaluate the scene every N ticks (held in between).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary instead of the line of text.")
@_apply(sensor_options)
def simulate(scene, duration_s, out_path, seed, height, width, max_lux, frame_rate_hz, interpolation,
             light_sample_ticks, as_json, **sensor_kw):
    """Shoot SCENE (a built-in name, an image or a video) with the spike camera and save the viform.

    Built-in scenes: translating, moving-edge, rotating, hdr, step, flicker.
    """
    from viform._io import check_output_folder
    from viform.light.scenes import load_scene
    from viform.stream.io import FORMATS, save_spikes

    if Path(out_path).suffix.lower() not in FORMATS:
        raise ViformError(f"--out = {out_path!r}: the suffix must be one of {', '.join(FORMATS)}")
    check_output_folder("--out", Path(out_path).resolve().parent)
    sensor = _sensor_from_options(**sensor_kw)
    light = load_scene(scene, height, width, max_lux=max_lux, frame_rate_hz=frame_rate_hz,
                       interpolation=interpolation)
    # .dat and .zarr writers pack each block at once, so the simulator may reuse its buffer
    reuse = Path(out_path).suffix.lower() in (".dat", ".zarr")
    stream = sensor.stream(light, duration_s, seed=seed, light_sample_ticks=light_sample_ticks, progress=True,
                           reuse_buffer=reuse)
    started = time.perf_counter()
    save_spikes(out_path, stream, block_ticks=1024)
    elapsed = time.perf_counter() - started
    pixel_ticks = stream.n_ticks * stream.height * stream.width
    if as_json:
        click.echo(json.dumps({"file": str(out_path), "n_ticks": stream.n_ticks, "height": stream.height,
                               "width": stream.width, "clock_hz": stream.clock_hz,
                               "threshold_electrons": stream.threshold_electrons, "seed": seed,
                               "elapsed_s": elapsed, "pixel_ticks_per_s": pixel_ticks / elapsed}, indent=2))
        return
    click.echo(f"wrote {out_path}: {stream.n_ticks} ticks × {stream.height}×{stream.width} at "
               f"{stream.clock_hz:g} Hz ({pixel_ticks / elapsed:.3g} pixel-ticks/s)")


@cli.command()
@click.argument("file", type=click.Path(exists=True))
@click.option("--method", type=click.Choice(["accumulation", "interval"]), required=True)
@click.option("--at", "at", required=True, help="Instant(s) in seconds, comma-separated: --at 0.01,0.02")
@click.option("--window", "window_s", type=float, default=None,
              help="Accumulation window before each instant, seconds (default: 40 ticks).")
@click.option("--out", "out_path", type=click.Path(), required=True,
              help="A .png for one instant, or a folder (PNGs + light.npz with e-/s and lux).")
@click.option("--height", type=int, default=None, help="Height of a .dat file.")
@click.option("--width", type=int, default=None, help="Width of a .dat file.")
@click.option("--clock-hz", type=float, default=None, help="Clock of a .dat/.npz file (default 40 kHz).")
@click.option("--no-flip", is_flag=True, help=".dat rows stored upright (some simulators).")
@click.option("--display", type=click.Choice(["linear", "seed", "inverse", "8bit"]), default="linear",
              show_default=True,
              help="PNG mapping: linear light (/max), the seed's 255−τ, 1/τ, or the common TFP/TFI 8-bit.")
@click.option("--scale", type=float, default=1.0, show_default=True,
              help="Full-scale firing rate per tick for --display 8bit (0.6 for REDS simulations).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary of what was written.")
def reconstruct(file, method, at, window_s, out_path, height, width, clock_hz, no_flip, display, scale, as_json):
    """Images of the viform in FILE at any instant, by accumulation or interval imaging.

    PNG mappings (--display): accumulation shows linear light or, with 8bit, the common TFP
    image; interval shows 1/τ (linear, inverse), the seed's 255 − τ (seed) or the common TFI
    image (8bit).
    """
    from viform._io import atomic_path, check_output_folder, save_image
    from viform.imaging import accumulation_image, interval_8bit, interval_image, inverse_tau_display_8bit
    from viform.imaging.interval import tau_display_8bit

    out = Path(out_path)
    if out.suffix.lower() != ".png" and out.suffix and not out.is_dir():
        raise ViformError(f"--out = {out_path!r} is not allowed: give a .png file (one instant) or a folder")
    if method == "accumulation" and display == "seed":
        raise ViformError("--display seed (255 − τ) is not allowed with --method accumulation: it maps intervals")
    if not scale > 0:
        raise ViformError(f"--scale = {scale!r} is not allowed: it must be > 0")
    check_output_folder("--out", (out.parent if out.suffix.lower() == ".png" else out).resolve())
    source = _open(file, height, width, clock_hz, flip=not no_flip)
    times = _parse_times(at)
    ticks = [source.tick_of(t, "--at") for t in times]
    if window_s is None:
        window_s = 40 / source.clock_hz
    images, pngs = [], []
    for t in times:
        if method == "accumulation":
            image = accumulation_image(source, t, window_s)
            rate_per_tick = image.spikes_per_s / source.clock_hz
            if display == "8bit":
                png = np.clip(np.rint(rate_per_tick * 255 / scale), 0, 255).astype(np.uint8)
            else:
                peak = image.spikes_per_s.max()
                png = np.zeros(image.spikes_per_s.shape, np.uint8) if peak == 0 else \
                    np.rint(image.spikes_per_s / peak * 255).astype(np.uint8)
        else:
            image = interval_image(source, t)
            tau = image.info["tau_ticks"]
            png = {"seed": tau_display_8bit, "inverse": inverse_tau_display_8bit,
                   "linear": inverse_tau_display_8bit}.get(display, lambda x: interval_8bit(x, scale))(tau)
        images.append(image)
        pngs.append(png)
    if out.suffix.lower() == ".png":
        if len(times) != 1:
            raise ViformError(f"--out = {out_path!r} is one PNG but --at gives {len(times)} instants: give a folder")
        save_image(out, pngs[0])
        _report(as_json, f"wrote {out}", {"files": [str(out)], "times_s": times, "ticks": ticks})
        return
    out.mkdir(parents=True, exist_ok=True)
    files = [out / f"{method}_{t:.6f}s.png" for t in times]
    for path, png in zip(files, pngs, strict=True):
        save_image(path, png)
    arrays = {"times_s": np.array(times), "ticks": np.array(ticks),
              "spikes_per_s": np.stack([i.spikes_per_s for i in images])}
    if images[0].electrons_per_s is not None:
        arrays["electrons_per_s"] = np.stack([i.electrons_per_s for i in images])
    if images[0].lux is not None:
        arrays["lux"] = np.stack([i.lux for i in images])
    if images[0].censored is not None:
        arrays["censored"] = np.stack([i.censored for i in images])
    with atomic_path(out / "light.npz") as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    _report(as_json, f"wrote {len(times)} PNG(s) and light.npz to {out}",
            {"files": [str(f) for f in files] + [str(out / "light.npz")], "times_s": times, "ticks": ticks})


def _report(as_json: bool, line: str, summary: dict) -> None:
    click.echo(json.dumps(summary, indent=2) if as_json else line)


@cli.command()
@click.argument("file", type=click.Path(exists=True))
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@click.option("--height", type=int, default=None, help="Height of a .dat file.")
@click.option("--width", type=int, default=None, help="Width of a .dat file.")
@click.option("--clock-hz", type=float, default=None, help="Clock of a .dat/.npz file (default 40 kHz).")
@click.option("--allow-partial", is_flag=True, help="Keep the whole frames of a .dat with trailing bytes.")
def info(file, as_json, height, width, clock_hz, allow_partial):
    """Resolution, duration, ticks, spike count, firing and data rates of a viform (or a coded file)."""
    summary = _coded_file_summary(file)
    if summary is None:
        source = _open(file, height, width, clock_hz, allow_partial=allow_partial)
        summary = {"file": str(file), **source.summary()}
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=str))
        return
    for key, value in summary.items():
        click.echo(f"{key:>28}: {value:.6g}" if isinstance(value, float) else f"{key:>28}: {value}")


def _coded_file_summary(file):
    """The first-spike coding module's description of a coded file, if FILE is one."""
    try:
        from viform.coding import aer_file
    except ImportError:
        return None
    describe = getattr(aer_file, "describe_coded_file", None)
    is_coded = getattr(aer_file, "is_coded_file", None)
    if describe is None or is_coded is None or not is_coded(file):
        return None
    return describe(file)


@cli.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="viform-demo", show_default=True)
@click.option("--scene", default="translating", show_default=True, help="A built-in scene name.")
@click.option("--duration", "duration_s", type=float, default=0.05, show_default=True, help="Seconds.")
@click.option("--seed", type=int, default=0, show_default=True)
def demo(out_dir, scene, duration_s, seed):
    """The main job on the built-in default scene: shoot, reconstruct, compare with the truth."""
    from viform.report.demo import run_demo

    summary = run_demo(out_dir, scene=scene, duration_s=duration_s, seed=seed, echo=click.echo)
    click.echo(json.dumps(summary["summary"], indent=2))
