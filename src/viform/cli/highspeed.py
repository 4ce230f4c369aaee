"""CLI commands: highspeed (registered on viform.cli.app.cli) — seed 002.

``viform highspeed SCENE``: the LUX13HS-like camera shoots SCENE with auto-exposure and
histogram equalization, buffers in DDR, decimates for the link and writes the video, a plot
of exposure and gray per frame and a report. ``viform highspeed-figures`` prints the seed's
numbers next to the model's.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from viform._validate import ViformError, check_choice, check_int, check_positive, check_range
from viform.cli._common import parse_settings
from viform.cli._scenes import with_scene_list
from viform.cli.app import cli


def _parse_size(text: str, name: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ViformError(f"{name} = {text!r} is not allowed: write WxH, e.g. 320x180") from None
    if w < 1 or h < 1:
        raise ViformError(f"{name} = {text!r} is not allowed: width and height must be ≥ 1")
    return h, w


@cli.command("highspeed")
@click.argument("scene")
@click.option("--roi", default="1280x720", show_default=True,
              help="Readout window on the 1280x864 sensor: WxH (centred) or X,Y,W,H. Sets the frame rate.")
@click.option("--mode", type=click.Choice(["reduced", "normal"]), default="reduced", show_default=True,
              help="LUX13HS readout mode (reduced: 4 px/clock; normal: 8 px/clock).")
@click.option("--clock-mhz", type=float, default=None, help="Sensor clock (default 100 reduced, 133 normal).")
@click.option("--interface", default="cameralink", show_default=True,
              help="coaxpress, cameralink-hs, cameralink, usb3 or gige.")
@click.option("--decimation", type=int, default=None, help="N of N:1 frame sampling (default: fit the link).")
@click.option("--max-decimation", type=int, default=64, show_default=True,
              help="Largest N the frame-sampling counter allows; a link that needs more is refused.")
@click.option("--ae/--no-ae", default=True, show_default=True, help="Auto-exposure.")
@click.option("--meter", type=click.Choice(["mean", "weighted", "percentile"]), default="mean",
              show_default=True, help="Auto-exposure feedback: mean gray of the frame, centre-weighted mean, "
                                      "or 99th percentile.")
@click.option("--target", "target_gray", type=float, default=128.0, show_default=True,
              help="Auto-exposure target gray (0-255); dead band ±--band.")
@click.option("--band", "band_gray", type=float, default=15.0, show_default=True,
              help="Auto-exposure dead band: no change while the gray is within target ± band (0-255 levels).")
@click.option("--ae-saturated-cut", type=float, default=None,
              help="Optional saturation-aware auto-exposure step k (0<k<1, e.g. 0.125): exposure ×k while "
                   "most pixels are at 255. Default: the plain rule, exposure scaled by target / mean gray.")
@click.option("--equalize/--no-equalize", default=True, show_default=True, help="Histogram equalization.")
@click.option("--eq-source", type=click.Choice(["same", "previous"]), default="same", show_default=True,
              help="Equalize each frame with its own histogram (gathered while it is buffered) "
                   "or with the previous transmitted frame's (flashes after a light step).")
@click.option("--eq-method", type=click.Choice(["shift", "float"]), default="shift", show_default=True,
              help="Equalization arithmetic: integer bit shifts (as in the camera's FPGA) or floating point.")
@click.option("--duration", "duration_s", type=float, default=None,
              help="Length of the capture, s: every sensor frame that ends in it  [default: 200 frames, 0.12 s at "
                   "the default window].")
@click.option("--frames", "n_frames", type=int, default=None,
              help="Sensor frames to capture, instead of --duration.")
@click.option("--exposure-us", type=float, default=100.0, show_default=True,
              help="Initial exposure (fixed with --no-ae), µs.")
@click.option("--render", default="320x180", show_default=True,
              help="Simulated pixel grid WxH (every k-th pixel of the window; timing uses the full window).")
@click.option("--lux", type=float, default=200.0, show_default=True,
              help="Mean illuminance of the scene at t = 0 on the sensor plane, lux (the scene is scaled).")
@click.option("--steps", default="0.03:10,0.07:0.1", show_default=True,
              help="Illuminance steps TIME_S:FACTOR,... applied to the scene ('none' for none).")
@click.option("--scene-fps", type=float, default=None, help="Frame rate of a video SCENE (if it declares none).")
@click.option("--video", "video_format", type=click.Choice(["gif", "mp4"]), default="gif", show_default=True,
              help="Format of the video of the transmitted frames.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed of the simulated noise.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="highspeed_out", show_default=True,
              help="Folder for the video, exposure.png and report.json.")
@click.option("--set", "settings", multiple=True, metavar="NAME=VALUE",
              help="Change one parameter of the camera by name, e.g. --set read_noise_electrons=20 --set "
                   "parasitic_light_sensitivity=0.01 (repeatable; viform sensors show highspeed lists them). The "
                   "flags above set their own parameters (--roi: roi, --target: target_gray, …); give each once.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON instead of the summary.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None,
              help="Also write the report JSON to this file (OUT/report.json is always written).")
@click.pass_context
@with_scene_list
def highspeed(ctx, scene, roi, mode, clock_mhz, interface, decimation, max_decimation, ae, meter, target_gray,
              band_gray, ae_saturated_cut, equalize, eq_source, eq_method, duration_s, n_frames, exposure_us, render,
              lux, steps, scene_fps, video_format, seed, settings, out_dir, as_json, json_file):
    """Shoot SCENE with a LUX13HS-like high-speed camera (1280x864, up to 3 500 fps).

    SCENE: {scenes} Writes OUT/video.gif|mp4 (the frames leaving the link), OUT/exposure.png
    and OUT/report.json (frames captured, buffered, transmitted, dropped).
    """
    from tqdm import tqdm

    from viform.isp.highspeed_pipeline import (
        HighSpeedConfig,
        ScaledScene,
        StepsScene,
        parse_steps,
        run_highspeed,
        write_outputs,
    )
    from viform.isp.link import INTERFACES, link_plan
    from viform.light.catalog import load_scene
    from viform.sensors.catalog import entry

    check_choice("interface", interface, tuple(INTERFACES))
    check_positive("lux", lux)
    kind = entry("highspeed")
    # the camera's parameters: its flags (those given, and the defaults of the others), then --set
    clock_hz = None if clock_mhz is None else check_positive("clock_mhz", clock_mhz) * 1e6
    flags = {"roi": ("roi", roi), "mode": ("mode", mode), "clock_mhz": ("pixel_clock_hz", clock_hz),
             "ae": ("ae", ae), "meter": ("meter", meter), "target_gray": ("target_gray", target_gray),
             "band_gray": ("band_gray", band_gray), "ae_saturated_cut": ("ae_saturated_cut", ae_saturated_cut),
             "exposure_us": ("exposure_s", check_positive("exposure_us", exposure_us) * 1e-6)}
    check_range("--target", target_gray, 0, 255)
    if ae_saturated_cut is not None:
        check_range("ae_saturated_cut", ae_saturated_cut, 0, 1, low_open=True, high_open=True)
    changed = parse_settings(kind, settings, skip_build=True)
    for option, (name, _) in flags.items():
        given = ctx.get_parameter_source(option) not in (click.core.ParameterSource.DEFAULT, None)
        if name in changed and given:
            flag = next(p for p in ctx.command.params if p.name == option).opts[0]
            raise ViformError(f"--set {f'{name}={changed[name]}'!r} and {flag} set the same parameter: give one "
                              "of them")
    camera_settings = {name: value for name, value in flags.values() if name not in changed} | changed
    camera = kind.build(**camera_settings)
    if duration_s is not None and n_frames is not None:
        raise ViformError("--duration and --frames both set the length of the capture: give one of them")
    n_frames = camera.frames_in(duration_s) if duration_s is not None else 200 if n_frames is None else n_frames
    timing, window = camera.timing, camera.window
    rh, rw = _parse_size(render, "render")
    rh, rw = min(rh, window.height), min(rw, window.width)
    from viform.light.catalog import BUILTIN_SCENES

    if scene in BUILTIN_SCENES:
        base = load_scene(scene, rh, rw, max_lux=1.0, frame_rate_hz=scene_fps)
    else:  # a file: keep its aspect ratio (centre crop to the grid's), never stretch it
        from viform.isp.highspeed_pipeline import AspectFitScene

        native = load_scene(scene, rh, rw, max_lux=1.0, frame_rate_hz=scene_fps, resize=False)
        base = AspectFitScene(native, rh, rw)
        if base.crop != (native.height, native.width):
            click.echo(f"note: {native.width}x{native.height} scene cropped to its centre {base.crop[1]}x"
                       f"{base.crop[0]} (the {rw}x{rh} grid's aspect ratio) and resized, not stretched", err=True)
    mean0 = float(base.illuminance_lux(0.0).mean())
    if mean0 <= 0:
        raise ViformError(f"scene {scene!r} is black at t = 0; cannot scale it to --lux")
    step_list = [] if str(steps).lower() == "none" else parse_steps(steps)
    sc = ScaledScene(base, lux / mean0)
    if step_list:
        sc = StepsScene(sc, step_list)
    cfg = HighSpeedConfig(interface=interface, decimation=decimation, max_decimation=max_decimation,
                          equalize=equalize, eq_source=eq_source, eq_method=eq_method, n_frames=n_frames, seed=seed)
    # Check everything before the progress bar starts, so an error is a single clean line.
    check_int("--frames", n_frames, 1)
    plan = link_plan(timing.frame_rate_hz(window), window.height, window.width, interface, 8, decimation,
                     max_decimation)
    if decimation is not None and decimation < plan["decimation_strict"]:
        click.echo(f"note: {decimation}:1 over {interface} is faster than the link ({plan['decimation_strict']}:1 "
                   "fits); the DDR ring will overflow and frames will be lost", err=True)
    with tqdm(total=n_frames, desc="frames", file=sys.stderr, leave=False) as bar:
        result = run_highspeed(sc, cfg, progress=bar.update, camera=camera)
    report = write_outputs(result, out_dir, video_format, [t for t, _ in step_list])
    if changed:
        report["settings"] = changed
    if json_file:
        from viform._io import write_json

        write_json(json_file, report)
    if as_json:
        click.echo(json.dumps(report, indent=2, default=float))
        return
    lk = report["link"]
    if changed:
        click.echo(f"changed: {', '.join(f'{k} = {v}' for k, v in changed.items())}")
    click.echo(f"sensor: {window.width}x{window.height} {camera.mode} @ {timing.pixel_clock_hz / 1e6:g} MHz -> "
               f"{report['sensor_frame_rate_hz']:.1f} fps ({report['timing']['cycles_per_frame']} cycles/frame)")
    click.echo(f"link: {interface} max {lk['link_max_frame_rate_hz']:.1f} fps; DDR ring "
               f"{lk['buffer_capacity_frames']} frames ({lk['buffer_record_s']:.3f} s)")
    click.echo("sampling: " + decimation_plan_text(lk["decimation"], lk["decimation_strict"],
                                                    lk["time_to_first_overrun_s"], lk["sustain_target_s"])
               + f" -> {lk['transmitted_frame_rate_hz']:.1f} fps sent")
    cap, sent, lost = report["frames_captured"], report["frames_transmitted"], report["frames_dropped"]
    waiting = max(0, -(-cap // lk["decimation"]) - sent - report["selected_but_overwritten"])
    click.echo(f"frames: captured {cap} = transmitted {sent} + still in the DDR ring {cap - sent - lost} "
               f"({waiting} of them picked for the link, not yet sent; the rest skipped by the "
               f"{lk['decimation']}:1 sampling) + lost {lost} (overwritten before sending)")
    for s in report["ae_settling"]:
        if s["settle_frames"] is None:
            click.echo(f"AE: step at {s['step_time_s']:g} s did not settle within the recording "
                       f"(gray not held in {target_gray:g} ± {band_gray:g})")
        else:
            click.echo(f"AE: step at {s['step_time_s']:g} s settled in {s['settle_frames']} frames "
                       f"({s['settle_s'] * 1e3:.3g} ms)")
    click.echo(f"wrote {Path(out_dir) / report['files']['video']}, exposure.png, report.json")


def decimation_plan_text(decimation: int, strict: int, overrun_s: float, sustain_s: float) -> str:
    """One wording of the N:1 frame-sampling plan for ``highspeed`` and ``highspeed-figures``:
    the link alone keeps up at ``strict``:1; below that the DDR ring absorbs the excess until
    it first overruns (the default choice keeps that beyond ``sustain_s``)."""
    if decimation >= strict:
        return f"{decimation}:1 (the link keeps up: never overruns)"
    kept = "≥" if overrun_s >= sustain_s else "<"
    return (f"{decimation}:1 with the DDR ring taking the excess (link alone: {strict}:1), "
            f"overruns after {overrun_s:.4g} s ({kept} {sustain_s / 3600:g} h)")


def format_figures(fig: dict) -> str:
    """The published figures next to the model's, as a small table with units."""
    red, nor = fig["reduced_1280x720_100MHz"], fig["normal_full_1280x864_133MHz"]
    r166, r25 = fig["reduced_166MHz"], fig["reduced_2500fps_full_frame"]
    links = fig["links_fps_1280x720x8"]
    ddr, dec, eq = fig["ddr"], fig["decimation"], fig["equalization_shift"]
    rows = [
        ("reduced 1280x720 @ 100 MHz", f"{red['cycles_per_frame']} cycles, {red['fps']:.1f} fps",
         "60 000 cycles, 1 666 fps"),
        ("normal 1280x864 @ 133 MHz", f"{nor['fps']:.0f} fps", "3 500 fps"),
        ("reduced 1280x864 @ 166 MHz", f"{r166['fps_1280x864']:.0f} fps", "-"),
        ("reduced 1280x864, clock fitted to 2 500 fps",
         f"{r25['pixel_clock_hz'] / 1e6:.1f} MHz (core {r25['core_clock_hz'] / 1e6:.1f} MHz "
         f"≤ {r25['core_limit_hz'] / 1e6:.0f} MHz)", "2 500 fps"),
        ("CameraLink, 1280x720x8 bit", f"{links['cameralink']:.0f} fps", "555 fps"),
        ("DDR4 ring", f"{ddr['capacity_frames']} frames ({ddr['record_s_at_sensor_rate']:.2f} s)",
         "2 330 frames"),
        ("frame sampling", decimation_plan_text(3, dec["strict"], dec["time_to_first_overrun_s_at_3to1"],
                                                dec.get("sustain_target_s", 3600.0)), "3:1"),
        ("equalization shifts", f">>{eq['shifts'][0]} + >>{eq['shifts'][1]}", ">>12 + >>15"),
        ("equalization worst error", f"{eq['max_abs_error_uncompensated']:.1f} → "
         f"{eq['max_abs_error_compensated']:.2f} levels", "'close to 0'"),
    ]
    status = fig.get("status", {})
    keys = ["reduced_1280x720_100MHz", "normal_full_1280x864_133MHz", "reduced_166MHz", "reduced_2500fps_full_frame",
            "cameralink_seed", "ddr", "decimation", "equalization_shift", "equalization_shift"]
    sh = fig.get("shutter")
    if sh:
        shares = ", ".join(f"{100 * v:.3g} % at {float(t) * 1e6:g} µs" for t, v in sh["parasitic_share_at_exposure"]
                           .items())
        rows += [("shutter efficiency (parasitic light)", f"{100 * sh['shutter_efficiency']:g} %, readout "
                  f"{sh['readout_time_s'] * 1e6:.0f} µs: +{sh['parasitic_exposure_equivalent_s'] * 1e6:.2f} µs "
                  "of exposure on average", "99 %"),
                 ("parasitic share of a frame", shares + (f" (simulated at 10 µs: "
                  f"{100 * sh['simulated_parasitic_share_at_10us']:.3g} %)"
                  if "simulated_parasitic_share_at_10us" in sh else ""), "-"),
                 ("brightest light at 1 clock of exposure",
                  f"{sh['brightest_lux_shortest_exposure']['with_parasitic_light']:.3g} lux "
                  f"(without parasitic light {sh['brightest_lux_shortest_exposure']['without_parasitic_light']:.3g})",
                  "-")]
        keys += ["shutter", "shutter_consequences", "shutter_consequences"]
    for s in fig.get("ae_10x_steps_latency1", []):
        n = s["settle_frames"]
        rows.append((f"AE after 10x step at {s['step_time_s'] * 1e3:g} ms",
                     "not settled" if n is None else f"{n} frames ({s['settle_s'] * 1e3:.2f} ms)", "-"))
        keys.append("ae_10x_steps_latency1")
    labels = [status.get(k, "").split(":")[0].split(" (")[0] for k in keys]
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    w2 = max(len(r[2]) for r in rows)
    head = f"{'quantity':<{w0}}  {'model':<{w1}}  {'published':<{w2}}  status"
    return "\n".join([head, "-" * len(head)] + [f"{a:<{w0}}  {b:<{w1}}  {c:<{w2}}  {d}"
                                                 for (a, b, c), d in zip(rows, labels, strict=True)])


@cli.command("highspeed-figures")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for before_after.png (auto-exposure off/on on an over-exposed scene, "
                   "equalization off/on on a dark one).")
@click.option("--json", "as_json", is_flag=True, help="Print the numbers as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON here.")
def highspeed_figures(out_dir, as_json, json_file):
    """Print the published LUX13HS camera figures next to the model's (timing, link, buffer, equalization)."""
    from viform._io import write_json
    from viform.isp.highspeed_pipeline import before_after, plot_before_after, seed_figures

    fig = seed_figures()
    if out_dir is not None:
        panels = before_after()
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        plot_before_after(Path(out_dir) / "before_after.png", panels)
        fig["before_after"] = {k: {a: b for a, b in v.items() if a != "image"} for k, v in panels.items()}
    if json_file:
        write_json(json_file, fig)
    if as_json:
        click.echo(json.dumps(fig, indent=2, default=float))
        return
    click.echo(format_figures(fig))
    if out_dir is not None:
        click.echo("")
        for k, v in fig["before_after"].items():
            click.echo(f"{k:<17} exposure {v['exposure_s'] * 1e6:6.1f} µs  mean gray {v['mean_gray']:5.1f}  "
                       f"at 255: {100 * v['saturated_fraction']:4.1f} %  levels {v['gray_levels_used']}")
        click.echo(f"wrote {Path(out_dir) / 'before_after.png'}")
