"""CLI: ``viform simulate`` — shoot a scene with the spike camera (seed 000)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from viform._validate import ViformError, size_text
from viform.cli._common import CatalogHelp, apply_options
from viform.cli._scenes import scene_set_option, scene_settings, with_scene_list
from viform.cli.app import cli

#: sensor options → SpikeSensorParameters fields (None: not given, keep the preset's / default)
_FIELDS = {"clock_hz": "clock_hz", "threshold_electrons": "threshold_electrons",
           "dark_current_e_per_s": "dark_current_e_per_s", "threshold_spread": "threshold_spread_fraction",
           "gain_spread": "gain_spread_fraction", "dark_current_spread": "dark_current_spread_fraction",
           "hot_pixel_fraction": "hot_pixel_fraction",
           "hot_pixel_dark_current_e_per_s": "hot_pixel_dark_current_e_per_s", "dead_time_s": "dead_time_s",
           "reset": "reset"}
_FLAGS = {"threshold_electrons": "--threshold-electrons", "clock_hz": "--clock-hz",
          "dark_current_e_per_s": "--dark-current-e-per-s", "threshold_spread": "--threshold-spread",
          "gain_spread": "--gain-spread", "dark_current_spread": "--dark-current-spread",
          "hot_pixel_fraction": "--hot-pixel-fraction",
          "hot_pixel_dark_current_e_per_s": "--hot-pixel-dark-current-e-per-s", "dead_time_s": "--dead-time-s",
          "quantum_efficiency": "--quantum-efficiency", "pixel_pitch_um": "--pixel-pitch-um",
          "fill_factor": "--fill-factor"}


def _sensor_from_options(preset, threshold_level, quantum_efficiency, pixel_pitch_um, fill_factor, no_noise,
                         no_random_initial, **given):
    """(SpikeSensor, preset or None): the preset's (or the default) parameters, then every option given."""
    import dataclasses

    from viform.sensors.spike import SpikeSensor, SpikeSensorParameters

    loaded = None
    if preset is not None:
        from viform.sensors.catalog import SENSORS
        from viform.sensors.spike_presets import SpikePreset, load_spike_preset

        camera = SENSORS.get(preset)
        if camera is not None and camera.family == "spike":  # a spike camera of the sensor catalogue
            loaded = SpikePreset(preset, camera.description, *camera.scene_shape, camera.build().parameters)
        else:
            loaded = load_spike_preset(preset)  # its errors name --preset and the offending key
    base = loaded.parameters if loaded is not None else SpikeSensorParameters()
    if threshold_level is not None:
        from viform.sensors.spike_presets import threshold_level_electrons

        if given.get("threshold_electrons") is not None:
            raise ViformError("give either --threshold-level or --threshold-electrons, not both")
        try:
            given["threshold_electrons"] = threshold_level_electrons(threshold_level)
        except ViformError:
            raise ViformError(f"--threshold-level = {threshold_level!r} is not allowed: it must be a whole "
                              "number in [0, 15] (the chip's 16 levels)") from None
    changes = {_FIELDS[k]: v for k, v in given.items() if v is not None}
    if pixel_pitch_um is not None and not pixel_pitch_um > 0:  # checked here: the optics hold metres
        raise ViformError(f"--pixel-pitch-um = {pixel_pitch_um!r} is not allowed: it must be > 0 µm")
    optics = {"quantum_efficiency": quantum_efficiency, "fill_factor": fill_factor,
              "pixel_pitch_m": None if pixel_pitch_um is None else pixel_pitch_um * 1e-6}
    optics = {k: v for k, v in optics.items() if v is not None}
    if no_noise:
        changes["photon_noise"] = False
    if no_random_initial:
        changes["random_initial_charge"] = False
    try:
        if optics:
            changes["optics"] = dataclasses.replace(base.optics, **optics)
        params = dataclasses.replace(base, **changes)
    except ViformError as exc:
        message = str(exc)
        for option, flag in _FLAGS.items():
            name = _FIELDS.get(option, option)
            if message.startswith(name + " ") or message.startswith(name + "="):
                message = flag + message[len(name):]
                break
        raise ViformError(message) from None
    return SpikeSensor(params), loaded


sensor_options = [
    click.option("--preset", default=None, metavar="NAME|FILE.json",
                 help="Start from a spike camera of the sensor catalogue ({sensors:spike}; viform sensors "
                      "describes them) or a preset file (e.g. from viform calibrate). Options given "
                      "below override it."),
    click.option("--threshold-level", type=int, default=None,
                 help="The chip's threshold level 0–15 (sets the threshold Q)."),
    click.option("--clock-hz", type=float, default=None,
                 help="Readout clock, Hz (the chip: 40 kHz, or 20 kHz mode).  [default: 40000]"),
    click.option("--threshold-electrons", "-q", type=float, default=None,
                 help="Accumulation threshold Q, electrons.  [default: 100]"),
    click.option("--dark-current-e-per-s", type=float, default=None, help="Mean dark current, e-/s.  [default: 20]"),
    click.option("--quantum-efficiency", type=float, default=None, help="[default: 0.7]"),
    click.option("--pixel-pitch-um", type=float, default=None, help="Pixel pitch, µm.  [default: 10]"),
    click.option("--fill-factor", type=float, default=None, help="[default: 1]"),
    click.option("--threshold-spread", type=float, default=None,
                 help="Fixed-pattern spread of Q across pixels (std/mean).  [default: 0]"),
    click.option("--gain-spread", type=float, default=None,
                 help="Pixel-to-pixel gain spread, PRNU (std/mean).  [default: 0]"),
    click.option("--dark-current-spread", type=float, default=None,
                 help="Pixel-to-pixel dark-current spread (std/mean, log-normal).  [default: 0]"),
    click.option("--hot-pixel-fraction", type=float, default=None, help="Fraction of hot pixels.  [default: 0]"),
    click.option("--hot-pixel-dark-current-e-per-s", type=float, default=None,
                 help="Mean dark current of a hot pixel, e-/s.  [default: 10000]"),
    click.option("--dead-time-s", type=float, default=None,
                 help="Reset dead time after each spike, s (no charge collected).  [default: 0]"),
    click.option("--reset", type=click.Choice(["self", "readout"]), default=None,
                 help="Self-reset at the threshold, or reset at the next readout tick.  [default: self]"),
    click.option("--no-noise", is_flag=True, help="Deterministic model: no photon noise."),
    click.option("--no-random-initial", is_flag=True, help="Start every pixel with an empty well."),
]


def check_request_duration(duration_s: float, sensor, light) -> None:
    """The size checks the CLI makes on --duration (ticks, pixel-ticks), for a duration taken from the video."""
    from viform.cli._types import MAX_TICKS, max_pixel_ticks

    ticks = duration_s * sensor.parameters.clock_hz
    pixels = light.height * light.width if hasattr(light, "height") else 0
    if ticks > MAX_TICKS:
        raise ViformError(f"the video lasts {duration_s:g} s, {ticks:.4g} ticks at {sensor.parameters.clock_hz:g} Hz, "
                          f"more than the {MAX_TICKS:.4g} a stream may hold: give a shorter --duration")
    if ticks * pixels > max_pixel_ticks():
        raise ViformError(f"the video lasts {duration_s:g} s: {ticks * pixels:.4g} pixel-ticks, more than the limit "
                          f"of {max_pixel_ticks():.4g}; give a shorter --duration, or raise the environment "
                          "variable VIFORM_MAX_PIXEL_TICKS")


@cli.command(cls=CatalogHelp)
@click.argument("scene")
@click.option("--duration", "duration_s", type=float, default=None,
              help="Length of the stream, seconds [default: a video's or image folder's own length; required for "
                   "built-in scenes and still images].")
@click.option("--out", "out_path", type=click.Path(dir_okay=True), required=True,
              help="Output file: .dat (spike-camera layout), .zarr (chunked, with metadata) or .npz.")
@click.option("--seed", type=int, default=0, show_default=True, help="Photon-noise seed.")
@click.option("--height", type=int, default=None,
              help="Resolution of built-in scenes [default: the preset's, or 250]; for an image or video, "
                   "resize to this height (keeping the aspect ratio unless --width is also given).")
@click.option("--width", type=int, default=None,
              help="Resolution of built-in scenes [default: the preset's, or 400]; for an image or video, "
                   "resize to this width.")
@click.option("--max-lux", type=float, default=4.0, show_default=True,
              help="Illuminance on the sensor of full-scale pixels of 8/16-bit images and videos, lux "
                   "(float images are lux already).")
@click.option("--frame-rate-hz", type=float, default=None, help="Frame rate of a video or image folder.")
@click.option("--interpolation", type=click.Choice(["hold", "linear"]), default="linear", show_default=True,
              help="Light between video frames.")
@click.option("--light-sample-ticks", type=int, default=1, show_default=True,
              help="Evaluate the scene every N ticks (held in between).")
@click.option("--truth", "truth_dir", type=click.Path(file_okay=False), default=None,
              help="Built-in scenes: also write their exact truth to this folder, one frame every "
                   "--truth-every-ticks: the light (gt/), forward flow to the next frame (flow/, .flo, px), "
                   "range (depth/, m) and object tracks (mot/: MOTChallenge gt.txt, seqinfo.ini).")
@click.option("--truth-every-ticks", type=int, default=40, show_default=True,
              help="Ticks per truth frame (40 ticks = 1 ms at 40 kHz).")
@click.option("--force", is_flag=True,
              help="Run a simulation estimated to take more than a minute (refused without it, with the estimate).")
@click.option("--device", type=click.Choice(["cpu", "cuda", "auto"]), default="cpu", show_default=True,
              help="Where the simulation runs: CPU cores, a CUDA GPU (pip install \"viform[cuda]\"; the same "
                   "bits for the same seed), or a GPU when one is found.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON summary here.")
@scene_set_option
@apply_options(sensor_options)
@with_scene_list
def simulate(scene, duration_s, out_path, seed, height, width, max_lux, frame_rate_hz, interpolation,
             light_sample_ticks, truth_dir, truth_every_ticks, force, device, as_json, json_file, scene_set,
             **sensor_kw):
    """Shoot SCENE (a built-in name, a scene description, an image or a video) with the spike camera and save
    the spike stream.

    {scenes}
    Memory stays bounded (blocks of about 50 MB) whatever the resolution and duration.
    """
    from viform._io import check_json_file, check_output_folder, write_json
    from viform.cli._types import check_simulation_work
    from viform.light.catalog import load_scene
    from viform.light.scenes import VideoScene
    from viform.sensors.spike_cuda import resolve_device
    from viform.stream.io import FORMATS, save_spikes

    if Path(out_path).suffix.lower() not in FORMATS:
        raise ViformError(f"--out = {out_path!r}: the suffix must be one of {', '.join(FORMATS)}")
    device = resolve_device(device, "--device")
    check_output_folder("--out", Path(out_path).resolve().parent)
    check_json_file(json_file)
    if not max_lux > 0:
        raise ViformError(f"--max-lux = {max_lux!r} is not allowed: it must be > 0 lux")
    for flag, value in (("--height", height), ("--width", width)):
        if value is not None and value < 1:
            raise ViformError(f"{flag} = {value!r} is not allowed: it must be at least 1 pixel")
    sensor, preset = _sensor_from_options(**sensor_kw)
    fit = (height, width)  # files: resized only when the user asked
    height = height if height is not None else (preset.height if preset is not None else 250)
    width = width if width is not None else (preset.width if preset is not None else 400)
    if duration_s is None and not Path(scene).exists() and not scene.lower().endswith((".yaml", ".yml", ".json")):
        raise ViformError(f"--duration is required: SCENE = {scene!r} is a built-in scene, which has no length of "
                          "its own (a video or image folder gives its own)")
    # the size is known before the scene loads
    if duration_s is not None and (all(v is not None for v in fit) or not Path(scene).exists()):
        check_simulation_work(duration_s, sensor.parameters.clock_hz, height * width, force)
    light = load_scene(scene, height, width, max_lux=max_lux, frame_rate_hz=frame_rate_hz,
                       interpolation=interpolation, fit=fit, settings=scene_settings(scene_set))
    if truth_dir is not None:
        from viform._validate import check_int

        check_int("--truth-every-ticks", truth_every_ticks, 1, 1 << 24)
        if not light.truth_kinds():
            raise ViformError(f"--truth: scene {scene!r} has no truth: image and video files carry only light; "
                              "use a built-in scene (translating, rotating, dilemma, multi-object, …)")
        check_output_folder("--truth", Path(truth_dir))
    scene_s = light.duration_s if isinstance(light, VideoScene) else None
    duration_from = "given"
    if duration_s is None:
        if scene_s is None:
            raise ViformError(f"--duration is required: SCENE = {scene!r} is a still image, which has no length "
                              "of its own (a video or image folder gives its own)")
        duration_s, duration_from = scene_s, "the video's length"
        check_request_duration(duration_s, sensor, light)
    check_simulation_work(duration_s, sensor.parameters.clock_hz, light.height * light.width, force)
    if scene_s is not None and duration_s > scene_s * (1 + 1e-9) and not as_json:
        click.echo(f"viform: warning: the video lasts {scene_s:.4g} s; its last frame is held for the other "
                   f"{duration_s - scene_s:.4g} s of --duration {duration_s:g}", err=True)
    # .dat and .zarr writers pack each block at once, so the simulator may reuse its buffer
    reuse = Path(out_path).suffix.lower() in (".dat", ".zarr")
    stream = sensor.stream(light, duration_s, seed=seed, light_sample_ticks=light_sample_ticks, progress=True,
                           reuse_buffer=reuse, device=device)
    if preset is not None:
        stream.metadata["preset"] = preset.name
    started = time.perf_counter()
    # the simulator caps each block at its memory budget (SpikeSensor.default_block_ticks)
    save_spikes(out_path, stream, block_ticks=1 << 20)
    elapsed = time.perf_counter() - started
    truth = None
    if truth_dir is not None:
        truth = _write_truth(truth_dir, Path(out_path).stem, light, stream, sensor, truth_every_ticks)
    pixel_ticks = stream.n_ticks * stream.height * stream.width
    p = sensor.parameters
    summary = {"file": str(out_path), "n_ticks": stream.n_ticks, "height": stream.height,
               "width": stream.width, "clock_hz": stream.clock_hz,
               "threshold_electrons": stream.threshold_electrons, "seed": seed,
               "preset": None if preset is None else preset.name,
               "duration_s": stream.n_ticks / stream.clock_hz, "duration_from": duration_from,
               "gain_spread_fraction": p.gain_spread_fraction, "dead_time_s": p.dead_time_s,
               "elapsed_s": elapsed, "pixel_ticks_per_s": pixel_ticks / elapsed, "truth": truth,
               "device": stream.metadata["device"]}
    if json_file:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    rows = [("file", str(out_path)), ("ticks", f"{stream.n_ticks}"),
            ("duration", f"{stream.n_ticks / stream.clock_hz:.6g} s"
                         + (f" ({duration_from}: no --duration given)" if duration_from != "given" else "")),
            ("size", size_text(stream.height, stream.width, "pixels")), ("clock", f"{stream.clock_hz:,.0f} Hz"),
            ("threshold Q", f"{stream.threshold_electrons:.4g} e-"),
            ("preset", "none" if preset is None else preset.name),
            ("speed", f"{pixel_ticks / elapsed:.3g} pixel-ticks/s"), ("device", stream.metadata["device"])]
    if truth is not None:
        rows.append(("truth", f"{truth['frames']} frames every {truth_every_ticks} ticks in {truth_dir}/ "
                              f"({', '.join(truth['kinds'])})"))
    width_ = max(len(k) for k, _ in rows)
    for k, v in rows:
        click.echo(f"{k:<{width_}}  {v}")


def _write_truth(folder, clip: str, scene, stream, sensor, step_ticks: int) -> dict:
    """The scene's truth beside the spikes (layout of :mod:`viform.datasets.scene_clips`); gt images are
    8-bit with full scale at the light that saturates the sensor (one spike per tick)."""
    from viform._io import atomic_path, write_json
    from viform.datasets.build import full_scale_lux
    from viform.datasets.scene_clips import write_truth
    from viform.vision.detectability import spike_detectability_of

    full_scale = full_scale_lux(sensor.parameters, 1.0)
    with atomic_path(folder, directory=True) as tmp:
        Path(tmp).mkdir()
        written = write_truth(tmp, clip, scene, stream.n_ticks, step_ticks, stream.clock_hz, full_scale,
                              detectability=spike_detectability_of(stream))
        meta = {"scene": scene.describe(), "step_ticks": step_ticks, "clock_hz": stream.clock_hz,
                "gt_full_scale_lux": full_scale, **written,
                "frame_time": "frame k: the end of step k, t = k·step_ticks / clock_hz (s)",
                "flow": "forward flow from frame k to frame k + 1, px, Middlebury .flo (unknown = 1e10)",
                "depth": "range along the line of sight, m, float32 .npy (inf: no surface)"}
        write_json(Path(tmp) / "truth.json", meta)
    return {"folder": str(folder), "frames": len(written["frames"]), "kinds": written["kinds"]}
