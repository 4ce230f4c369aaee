"""CLI: ``viform reconstruct`` — images of a spike stream at any instant (seed 000 §3.3)."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from viform._validate import ViformError
from viform.cli._common import open_source as _open
from viform.cli._common import parse_times as _parse_times
from viform.cli._common import report as _report
from viform.cli.app import cli


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
