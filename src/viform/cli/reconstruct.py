"""CLI: ``viform reconstruct`` — images of a spike stream at any instant, or a whole-stream video (seed 000 §3.3)."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import click
import numpy as np

from viform._validate import ViformError
from viform.cli._common import open_source as _open
from viform.cli._common import parse_times as _parse_times
from viform.cli._common import spike_file_options
from viform.cli.app import cli

VIDEO_SUFFIXES = (".mp4", ".gif")
#: The method used when --method is not given: sharp and low-noise on still and moving scenes at any
#: light level, at the speed of the simple methods (``motion`` is better on motion, ~200× slower).
DEFAULT_METHOD = "multi-interval"
#: How to get the 8-bit picture of published spike-camera numbers (rate × 255 / 0.6).
PUBLISHED_DISPLAY = "--display 8bit --scale 0.6"


class _DisplayChoice(click.Choice):
    """The --display choices; ``seed`` is still accepted (hidden) for ``255-tau``, its old name."""

    def convert(self, value, param, ctx):
        return super().convert("255-tau" if value == "seed" else value, param, ctx)


def _png(method, display, scale, image, rate_per_tick, peak):
    """8-bit picture of one image: one fixed mapping for every frame of a run (no flicker)."""
    from viform.imaging import interval_8bit, inverse_tau_display_8bit, tau_display_8bit

    if method == "interval" and display in ("255-tau", "inverse"):
        tau = image.info["tau_ticks"]
        return tau_display_8bit(tau) if display == "255-tau" else inverse_tau_display_8bit(tau)
    if method == "interval" and display == "8bit":
        return interval_8bit(image.info["tau_ticks"], scale)
    full = scale if display == "8bit" else peak
    return np.clip(np.rint(rate_per_tick * 255.0 / full), 0, 255).astype(np.uint8)


def _display_note(display: str, method: str, scale: float) -> str:
    """Which grey-level mapping the PNGs/video use, and how to get the published one."""
    if display == "8bit" and scale == 0.6:
        return "display: 8bit, rate × 255 / 0.6 (the convention of published spike-camera numbers)"
    what = {"linear": "linear", "255-tau": "255-tau", "inverse": "inverse (1/τ)",
            "8bit": f"8bit with --scale {scale:g}"}[display]
    return (f"display: {what}; to compare with published spike-camera numbers (8-bit, rate × 255 / 0.6"
            + ("; PSNRs of this linear display come out 4–10 dB lower" if display == "linear" else "")
            + f") add {PUBLISHED_DISPLAY}")


def _no_measurement(source) -> str:
    """Why an image has no measured pixel, and how long a clip would need to be (from the stream's firing rate)."""
    stats = source.summary()
    rate = stats["mean_firing_rate_per_tick"]
    length = f"the stream lasts {source.n_ticks} ticks ({source.n_ticks / source.clock_hz * 1e3:.3g} ms)"
    if not rate > 0:
        return f"no pixel has a measurement: the stream holds no spike at all ({length})"
    interval = 1.0 / rate
    every_ms = interval / source.clock_hz * 1e3
    return (f"no pixel has a measurement at an instant marked 0.0 %: none spikes both before and after it. A pixel "
            f"fires on average every {interval:,.0f} ticks ({every_ms:.3g} ms) and {length}; a clip "
            f"of at least {2 * interval:,.0f} ticks ({2 * interval / source.clock_hz * 1e3:.3g} ms) with the instant "
            "in its middle gives a typical pixel an interval, or use --method accumulation (a spike count, no "
            "interval needed)")


def default_output(file, method: str, times) -> str:
    """Where ``reconstruct`` writes when neither --out nor --video is given: in the working folder, named
    after the input file — ``STEM_METHOD_T.png`` for one instant, the folder ``STEM_METHOD/`` for several."""
    stem = Path(file).name.split(".")[0] or "spikes"
    if len(times) == 1:
        return f"{stem}_{method}_{times[0]:.6f}s.png"
    return f"{stem}_{method}"


@contextlib.contextmanager
def _light_npz(path, n_frames: int, shape, arrays: dict):
    """A :class:`~viform.imaging.sequence.NpzFrameWriter` on a temporary name, renamed onto ``path`` on success."""
    from viform._io import atomic_path
    from viform.imaging.sequence import NpzFrameWriter

    with atomic_path(path) as tmp:
        writer = NpzFrameWriter(tmp, n_frames, shape, arrays)
        try:
            yield writer
        except BaseException:
            writer.abort()
            raise
        writer.close()


@contextlib.contextmanager
def _video_file(path: Path, fps: float):
    """An imageio video writer on a temporary name, renamed onto ``path`` on success."""
    import imageio.v2 as imageio

    from viform._io import atomic_path

    with atomic_path(path) as tmp:
        kwargs = {"fps": fps, "macro_block_size": 2} if path.suffix.lower() == ".mp4" else \
            {"duration": 1000.0 / fps, "loop": 0}
        writer = imageio.get_writer(tmp, **kwargs)
        try:
            yield writer
        finally:
            writer.close()


def _write_images(source, method, ticks, times, out, folder, video, fps, no_png, display, scale, *,
                  window_ticks, align, spikes_per_side, adaptive, files):
    """Reconstruct the instants and write PNGs, ``light.npz`` and the video; ``files`` collects what was written.

    Returns the per-instant summary rows, the linear display's white level (spikes a tick) and the lux per
    spike a tick of the first image (light ∝ firing rate), or None where the stream has no lux scale.
    """
    from viform._io import save_image
    from viform.imaging.sequence import reconstruct_ticks
    from viform.imaging.units import sensor_parameters_of

    peak = lux_per_rate = None
    rows = []
    with contextlib.ExitStack() as stack:
        writer = video_writer = None
        arrays = {}
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            params = sensor_parameters_of(source)
            arrays = {"spikes_per_s": np.float32}
            if params is not None or source.threshold_electrons is not None:
                arrays["electrons_per_s"] = np.float32
            if params is not None:
                arrays["lux"] = np.float32
            arrays["censored"] = np.bool_
            writer = stack.enter_context(_light_npz(folder / "light.npz", len(ticks),
                                                    (source.height, source.width), arrays))
            writer.add_array("times_s", np.array(times))
            writer.add_array("ticks", np.array(ticks))
        if video is not None:
            video_writer = stack.enter_context(_video_file(Path(video), fps))
        frames = reconstruct_ticks(source, method, ticks, window_ticks=window_ticks, align=align,
                                   spikes_per_side=spikes_per_side, adaptive=adaptive, progress=len(ticks) > 1)
        for (k, image), t in zip(frames, times, strict=True):
            rate = image.spikes_per_s / source.clock_hz
            if peak is None:
                peak = float(np.percentile(rate, 99.9)) or float(rate.max()) or 1.0
                if image.lux is not None and float(np.mean(rate)) > 0:
                    lux_per_rate = float(np.mean(image.lux)) / float(np.mean(rate))
            png = _png(method, display, scale, image, rate, peak)
            if writer is not None:
                writer.append("spikes_per_s", image.spikes_per_s)
                if "electrons_per_s" in arrays:
                    writer.append("electrons_per_s", image.electrons_per_s)
                if "lux" in arrays:
                    writer.append("lux", image.lux)
                writer.append("censored", np.zeros(rate.shape, bool) if image.censored is None else image.censored)
                if not no_png:
                    path = folder / f"{method}_{k:07d}_{t:.6f}s.png"
                    save_image(path, png)
                    files.append(str(path))
            elif out is not None:
                save_image(out, png)
                files.append(str(out))
            if video_writer is not None:
                video_writer.append_data(png)
            # a censored pixel's interval is cut by an end of the stream: its light is only an upper
            # bound, so it is left out of the means (and counted)
            measured = np.ones(rate.shape, bool) if image.censored is None else ~np.asarray(image.censored)
            n_measured = int(measured.sum())
            rows.append((k, t, float(np.mean(rate[measured])) if n_measured else None,
                         None if image.lux is None or not n_measured else float(np.mean(image.lux[measured])),
                         n_measured / measured.size))
        # leaving the stack closes the video, then light.npz, each renamed onto its name only now
        if writer is not None:
            files.append(str(folder / "light.npz"))
        if video_writer is not None:
            files.append(str(video))
    return rows, peak, lux_per_rate


@cli.command()
@click.argument("file", type=click.Path(exists=True))
@click.option("--method", type=click.Choice(["multi-interval", "motion", "interval", "accumulation"]),
              default=DEFAULT_METHOD, show_default=True,
              help="multi-interval (default): the K spikes on each side of the instant (adaptive K), sharp and "
                   "low-noise at every light level; motion: accumulation along the estimated motion over "
                   "±60 ticks (short windows where that fails), averaged with multi-interval, the best on moving "
                   "scenes but about 200× slower; interval: Q/τ of the one interval holding the instant, the "
                   "sharpest and noisiest; accumulation: spike count over a window (the usual 8-bit spike-count "
                   "picture).")
@click.option("--at", "at", default=None, help="Instant(s) in seconds, comma-separated: --at 0.01,0.02")
@click.option("--every", "every", type=int, default=None,
              help="Whole stream: one image every N ticks (instead of --at).")
@click.option("--window", "window_s", type=float, default=None,
              help="Accumulation window, seconds (default: 41 ticks, the window of the usual 8-bit "
                   "spike-count pictures).")
@click.option("--align", type=click.Choice(["centre", "center", "end", "start"]), default="centre", show_default=True,
              help="Accumulation window placement: centred on the instant (the convention of published "
                   "spike-camera figures), ending at it (causal, live use) or starting at it.")
@click.option("--spikes-per-side", "spikes_per_side", type=int, default=4, show_default=True,
              help="multi-interval: spikes used on each side of the instant (K; 2K − 1 intervals).")
@click.option("--fixed-k", is_flag=True, help="multi-interval: always use K spikes a side (no adaptive shrinking).")
@click.option("--out", "out_path", type=click.Path(), default=None,
              help="A .png for one instant, or a folder (PNGs + light.npz with spikes/s, e-/s and lux). "
                   "Default (without --out and --video): STEM_METHOD_Ts.png for one instant, the folder "
                   "STEM_METHOD for several, in the working folder (STEM: the input file's name).")
@click.option("--video", "video", type=click.Path(), default=None,
              help="Also write the images as a video (.mp4 or .gif).")
@click.option("--fps", type=float, default=30.0, show_default=True, help="Frame rate of --video.")
@click.option("--no-png", is_flag=True, help="Folder output without the per-instant PNGs (light.npz only).")
@spike_file_options()
@click.option("--display", type=_DisplayChoice(["linear", "255-tau", "inverse", "8bit"]), default="linear",
              show_default=True,
              help="PNG/video mapping: linear light (the first image's 99.9th percentile is white, for every "
                   "image; 4–10 dB brighter than the published convention, which is --display 8bit --scale 0.6); "
                   "with --method interval, 255-tau (grey level 255 − τ, τ the interval in ticks: "
                   "short intervals = bright) or inverse (1/τ); or 8bit, the usual 8-bit spike-camera "
                   "picture: spike count over the window (or 1/τ) scaled so --scale spikes a tick is white.")
@click.option("--scale", type=float, default=1.0, show_default=True,
              help="Full-scale firing rate per tick for --display 8bit (0.6 for the spike streams simulated "
                   "from the REDS video data set).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary instead of the table.")
@click.option("--json-file", "json_file", type=click.Path(dir_okay=False), default=None,
              help="Also write the JSON summary to this file.")
def reconstruct(file, method, at, every, window_s, align, spikes_per_side, fixed_k, out_path, video, fps, no_png,
                height, width, no_flip, clock_hz, key, axes, display, scale, as_json, json_file):
    """Images of the spike stream in FILE at chosen instants (--at) or over the whole stream (--every).

    Accumulation windows are centred on each instant by default (--align), as in published
    spike-camera figures: the usual 8-bit spike-count picture of streams simulated from
    the REDS video data set is --method accumulation --display 8bit --scale 0.6 (41 ticks). Whole-stream output
    (--every N) is written frame by frame in bounded memory, with a progress bar.
    """
    from viform._io import check_json_file, check_output_folder, write_json

    # ---- validate everything before any work: options first, then the file and its instants, then outputs
    if (at is None) == (every is None):
        raise ViformError("give either --at (instants in seconds) or --every N (ticks, whole stream), not both "
                          "or neither")
    if every is not None and every < 1:
        raise ViformError(f"--every = {every!r} is not allowed: give a whole number of ticks ≥ 1")
    if video is not None and Path(video).suffix.lower() not in VIDEO_SUFFIXES:
        raise ViformError(f"--video = {video!r} is not allowed: give a path ending in {' or '.join(VIDEO_SUFFIXES)}")
    if not fps > 0:
        raise ViformError(f"--fps = {fps!r} is not allowed: it must be > 0")
    if display in ("255-tau", "inverse") and method != "interval":
        raise ViformError(f"--display {display} is not allowed with --method {method}: it maps intervals "
                          "(use --method interval, or --display linear / 8bit)")
    if not scale > 0:
        raise ViformError(f"--scale = {scale!r} is not allowed: it must be > 0")
    if spikes_per_side < 1:
        raise ViformError(f"--spikes-per-side = {spikes_per_side!r} is not allowed: give a whole number ≥ 1")
    if window_s is not None and not window_s > 0:
        raise ViformError(f"--window = {window_s!r} is not allowed: it must be > 0 seconds")
    check_json_file(json_file)
    times = _parse_times(at) if at is not None else None
    source = _open(file, height, width, clock_hz, flip=not no_flip, key=key, axes=axes)
    if times is not None:
        ticks = [source.tick_of(t, "--at") for t in times]
    else:
        ticks = list(range(every // 2, source.n_ticks, every)) or [source.n_ticks // 2]
        times = [source.start_time_s + (k + 0.5) / source.clock_hz for k in ticks]
    if len(set(ticks)) != len(ticks) or ticks != sorted(ticks):
        raise ViformError(f"--at = {at!r} is not allowed: give instants in increasing order, one per tick")
    if window_s is not None and window_s * source.clock_hz > source.n_ticks:
        raise ViformError(f"--window = {window_s:g} s is not allowed: it is longer than the stream "
                          f"({source.n_ticks / source.clock_hz:g} s, {source.n_ticks} ticks)")
    window_ticks = 41 if window_s is None else max(1, int(round(window_s * source.clock_hz)))
    if out_path is None and video is None:  # the default output: beside the working folder, named after the input
        out_path = default_output(file, method, times)
    out = Path(out_path) if out_path is not None else None
    if out is not None and out.suffix.lower() != ".png" and out.suffix and not out.is_dir():
        raise ViformError(f"--out = {out_path!r} is not allowed: give a .png file (one instant) or a folder")
    if out is not None and out.suffix.lower() == ".png" and len(ticks) != 1:
        raise ViformError(f"--out = {out_path!r} is one PNG but there are {len(ticks)} instants: give a folder")
    if out is not None:
        check_output_folder("--out", (out.parent if out.suffix.lower() == ".png" else out).resolve())
    if video is not None:
        check_output_folder("--video", Path(video).resolve().parent)
    from viform.imaging.support import imaging_need, spike_support

    # the firing measured near the instants only (a damaged file's far ticks are not read for it)
    need_window, need = imaging_need(method, source.n_ticks, window_ticks, spikes_per_side)
    near = max(window_ticks, 256)
    warning = spike_support(source, need_window, need, ticks[0] - near, ticks[-1] + near + 1).warning(
        f"{method} images", "brighten the scene or lower the threshold Q (simulate -q / --threshold-level)"
        + (", or give a longer --window" if method == "accumulation" else ", or record a longer stream"))
    if warning:
        click.echo(warning, err=True)

    # ---- reconstruct and write frame by frame; on any failure no partial set of files is left
    folder = out if out is not None and out.suffix.lower() != ".png" else None
    made_folder = folder is not None and not folder.exists()
    files: list[str] = []
    try:
        summary_rows, peak, lux_per_rate = _write_images(
            source, method, ticks, times, out, folder, video, fps, no_png, display, scale,
            window_ticks=window_ticks, align=align, spikes_per_side=spikes_per_side, adaptive=not fixed_k,
            files=files)
    except BaseException:
        for written in files:  # e.g. damage found at a later instant
            Path(written).unlink(missing_ok=True)
        if made_folder and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
        raise
    summary = {"method": method, "align": align if method == "accumulation" else None,
               "window_ticks": window_ticks if method == "accumulation" else None,
               "frames": len(ticks), "times_s": times, "ticks": ticks,
               "mean_firing_rate_per_tick": [r[2] for r in summary_rows],
               "mean_lux": [r[3] for r in summary_rows], "measured_fraction": [r[4] for r in summary_rows],
               "files": files, "display": display, "display_note": _display_note(display, method, scale)}
    if any(r[4] == 0 for r in summary_rows):
        summary["no_measurement"] = _no_measurement(source)
    if display in ("linear", "8bit") and not (method == "interval" and display == "8bit"):
        white = peak if display == "linear" else scale
        summary["white_firing_rate_per_tick"] = white
        summary["white_lux"] = None if lux_per_rate is None or white is None else white * lux_per_rate
    if json_file is not None:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"{method} images of {file}: {len(ticks)} frame(s)")
    censoring = any(r[4] < 1 for r in summary_rows)
    click.echo(f"{'tick':>8} {'time (s)':>11} {'rate (/tick)':>13} {'mean (lux)':>11}"
               + (f" {'measured px':>12}" if censoring else ""))
    shown = summary_rows if len(summary_rows) <= 12 else summary_rows[:5] + [None] + summary_rows[-5:]
    for row in shown:
        if row is None:
            click.echo(f"{'…':>8}")
            continue
        k, t, r, lux, frac = row
        measured = f" {100 * frac:>11.1f}%" if censoring else ""
        click.echo(f"{k:>8d} {t:>11.6f} {'—' if r is None else format(r, '.4g'):>13} "
                   f"{'—' if lux is None else format(lux, '.4g'):>11}{measured}")
    if censoring:
        click.echo("measured px: pixels with a complete interval around the instant; the others' intervals are cut "
                   "by an end of the stream, so their light is only an upper bound and is left out of the means")
    if "no_measurement" in summary:
        click.echo(summary["no_measurement"])
    if summary.get("white_firing_rate_per_tick") is not None:
        lux_text = "" if summary["white_lux"] is None else f" ≈ {summary['white_lux']:.3g} lux"
        why = ("the first image's 99.9th percentile, kept for every image" if display == "linear"
               else "--scale")
        click.echo(f"grey scale: black = no spikes, white = {summary['white_firing_rate_per_tick']:.3g} spikes a "
                   f"tick{lux_text} ({why})")
    elif display == "255-tau":
        click.echo("grey scale: 255 − the interval in ticks (short interval = bright)")
    click.echo(summary["display_note"])
    click.echo(f"wrote {len(files)} file(s)" + (f" to {folder}" if folder is not None else f": {', '.join(files)}"))
