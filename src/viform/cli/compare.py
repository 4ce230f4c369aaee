"""CLI: ``viform compare SCENE`` — one scene shot by every sensor, scored against the truth."""

from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path

import click

from viform._validate import ViformError, check_positive
from viform.cli._common import CatalogHelp
from viform.cli._scenes import built_in_scene_options, scene_options, scene_set_option, with_scene_list
from viform.cli.app import cli


def parse_sensors(text: str | None) -> list[str] | None:
    """``--sensors a,b,c`` → names of the sensor catalogue (None: compare's default list)."""
    from viform.measure.comparison import compare_entry

    if text is None:
        return None
    keys = [k.strip() for k in text.split(",") if k.strip()]
    if not keys:
        raise ViformError("--sensors is empty: give sensor names separated by commas, e.g. --sensors spikeone,cmos")
    for k in keys:
        compare_entry(k, what="--sensors")
    return keys


def parse_sensor_settings(items, sensors, flag: str = "--set") -> dict[str, dict]:
    """``--set [SENSOR:]NAME=VALUE`` → {sensor: {parameter: value}}; without ``SENSOR:`` the parameter is
    set on every sensor of ``sensors`` that has it (at least one must)."""
    import re

    from viform.cli._common import parse_settings
    from viform.measure.comparison import compare_entry

    by: dict[str, list] = {}
    for item in items or ():
        m = re.fullmatch(r"\s*(?:([\w.-]+):)?([^=:]+=.*)", str(item))
        if m is None:
            raise ViformError(f"{flag} {item!r} is not allowed: write [SENSOR:]NAME=VALUE, e.g. "
                              f"{flag} cmos:exposure_s=0.002")
        who, rest = m.group(1), m.group(2)
        name = rest.partition("=")[0].strip()
        if who is not None:
            if who not in sensors:
                raise ViformError(f"{flag} {item!r}: sensor {who!r} is not compared here (--sensors gives "
                                  f"{', '.join(sensors)})")
            targets = [who]
        else:
            targets = [k for k in sensors if name in compare_entry(k).parameters]
            if not targets:
                raise ViformError(f"{flag} {item!r}: {name!r} is a parameter of none of {', '.join(sensors)} "
                                  "(viform sensors show NAME lists a sensor's parameters)")
        for k in targets:
            by.setdefault(k, []).append(rest)
    return {k: parse_settings(compare_entry(k), texts, flag) for k, texts in by.items()}


def parse_instants(text: str | None) -> list[float] | None:
    if text is None:
        return None
    from viform.cli._common import parse_times

    return parse_times(text)


def check_outputs(out_dir, json_file) -> None:
    from viform._io import check_json_file, check_output_folder

    if Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise ViformError(f"--out: {out_dir} is a file; give a folder")
    check_output_folder("--out", out_dir)
    check_json_file(json_file)


def command_start() -> float:
    """``time.perf_counter()`` value at this process's start (Linux /proc), else now.

    So the wall time reported covers start-up and imports too, as a user's stopwatch does.
    """
    import os

    now = time.perf_counter()
    try:
        with open("/proc/self/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime") as f:
            uptime_s = float(f.read().split()[0])
        age_s = uptime_s - int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return now
    return now - age_s if 0 <= age_s < 3600 else now


def kernels_cached() -> bool:
    """Whether numba's on-disk cache holds the spike simulation kernels for the current source.

    Cheap check: an index file (``*.nbi``) of the kernels' module ``viform/sensors/_spike_kernels.py`` no
    older than the source, in ``__pycache__`` next to it or under ``NUMBA_CACHE_DIR`` when that is set.
    """
    import os

    import viform.sensors as sensors

    src = Path(sensors.__file__).with_name("_spike_kernels.py")
    where = os.environ.get("NUMBA_CACHE_DIR")
    pattern = f"{src.stem}.*.nbi"
    found = Path(where).rglob(pattern) if where else (src.parent / "__pycache__").glob(pattern)
    try:
        made = src.stat().st_mtime
        return any(p.stat().st_mtime >= made for p in found)
    except OSError:
        return False


def announce_preparation() -> None:
    """One line on stderr before the first simulation when the kernels must be compiled first."""
    if not kernels_cached():
        click.echo("compiling the simulation kernels (first run only; cached afterwards) …", err=True)


def finish(doc: dict, out_dir, elapsed_s: float, as_json: bool, json_file, extra: dict | None = None) -> None:
    from viform._io import write_json
    from viform.report.compare_report import RUN_TIME_NOTE, finite_json, metrics_table

    if doc.get("run_time_s"):  # the wall time the report states, so the console says the same
        elapsed_s = doc["run_time_s"]
    summary = {"report": str(Path(out_dir) / "report.html"), "metrics": str(Path(out_dir) / "metrics.json"),
               "elapsed_s": elapsed_s, "sensors": {k: {"label": v["label"], "skipped": v["skipped"],
                                                        **v["metrics"]} for k, v in doc["sensors"].items()},
               "verdict": doc["verdict"], "elapsed_note": RUN_TIME_NOTE, **(extra or {})}
    if doc.get("vision"):
        summary["vision"] = doc["vision"]
    summary = finite_json(summary)  # NaN (a metric not defined here) becomes null: valid JSON
    if json_file:
        write_json(json_file, summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2, allow_nan=False))
        return
    click.echo(metrics_table(doc))
    click.echo("")
    for line in doc["verdict"]:
        click.echo(f"- {line}")
    _echo_vision(doc)
    click.echo(f"\nwrote {summary['report']} and {summary['metrics']} in {elapsed_s:.1f} s "
               "(wall time from the command's start, compiling included on a first run)")


def _echo_vision(doc: dict) -> None:
    """The vision table and its verdict lines, where the scene has object truth."""
    vision = doc.get("vision")
    if not vision:
        return
    click.echo("")
    for row in vision["table"]:
        if "skipped" in row:
            click.echo(f"{row['label']}: not tracked ({row['skipped']})")
            continue
        lat = "never" if row["median_latency_ms"] is None else f"{row['median_latency_ms']:.2f} ms"
        click.echo(f"tracking · {row['label']}: HOTA {row['hota']:.3f}, MOTA {row['mota']:.3f}, IDF1 "
                   f"{row['idf1']:.3f}, {row['id_switches']} ID switches, median latency {lat}, never found: "
                   f"{', '.join(map(str, row['never_found'])) or 'none'}")
    for line in vision["verdict"]:
        click.echo(f"- {line}")


@cli.command(cls=CatalogHelp)
@click.argument("scene")
@click.option("--sensors", default=None,
              help="Comma-separated sensors (default: spikeone, cmos-short, cmos, seed001-2seg, seed001-3seg, "
                   "seed003-4t, seed003-overflow, highspeed, gated); any of: {sensors}.")
@click.option("--duration", "duration_s", type=float, default=0.04, show_default=True, help="Clip length, s.")
@click.option("--at", "at", default=None, help="Instants to compare, s, comma-separated (default: 30/50/70 %).")
@click.option("--out", "out_dir", type=click.Path(), default="viform-compare", show_default=True,
              help="Output folder (report.html, metrics.json, figures/).")
@built_in_scene_options
@click.option("--seed", type=int, default=0, show_default=True, help="Noise seed.")
@click.option("--set", "settings", multiple=True, metavar="[SENSOR:]NAME=VALUE",
              help="Change one parameter of a sensor by name, e.g. --set cmos:exposure_s=0.002, or of every "
                   "compared sensor that has it: --set read_noise_electrons=10 (repeatable; viform sensors show "
                   "SENSOR lists the parameters).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of the table.")
@click.option("--json-file", type=click.Path(), default=None, help="Also write the JSON summary here.")
@scene_set_option
@with_scene_list
def compare(scene, sensors, duration_s, at, out_dir, height, width, brightness, speed, visibility_m, seed, settings,
            as_json, json_file, scene_set):
    """Shoot SCENE with every sensor and write a self-contained report.html and metrics.json.

    SCENE: dilemma (high speed and high dynamic range at once), night-road-fog (with range,
    for the gated camera), another scene. {scenes}
    """
    started = command_start()
    from viform.report.compare_report import compare as run

    keys = parse_sensors(sensors)
    from viform.measure.comparison import DEFAULT_SENSORS

    changed = parse_sensor_settings(settings, keys or list(DEFAULT_SENSORS))
    instants = parse_instants(at)
    check_positive("--duration", duration_s)
    check_outputs(out_dir, json_file)
    options = {k: v for k, v in (("brightness", brightness), ("speed", speed), ("visibility_m", visibility_m))
               if v is not None}
    if options and scene not in ("dilemma", "night-road-fog"):
        raise ViformError(f"--{'/--'.join(k.replace('_', '-') for k in options)} apply to the dilemma and "
                          f"night-road-fog scenes only, not to SCENE = {scene!r}")
    if speed is not None and scene != "dilemma":
        raise ViformError("--speed applies to the dilemma scene only")
    if visibility_m is not None and scene != "night-road-fog":
        raise ViformError("--visibility-m applies to the night-road-fog scene only")
    options.update(scene_options(scene, scene_set))
    doc = run(scene, out_dir, keys, duration_s, height, width, seed, instants, progress=True,
              command=shlex.join(["viform", *sys.argv[1:]]) if sys.argv else "", scene_options=options,
              started_s=started, settings=changed, on_valid=announce_preparation)
    finish(doc, out_dir, time.perf_counter() - started, as_json, json_file, {"settings": changed} if changed else None)
