"""CLI: ``viform simulate`` — shoot a scene with the spike camera (seed 000)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from viform._validate import ViformError
from viform.cli.app import cli


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
