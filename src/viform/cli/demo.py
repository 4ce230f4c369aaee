"""CLI: ``viform demo`` — the comparison that shows the point of the project, on the dilemma scene."""

from __future__ import annotations

import time

import click

from viform.cli._scenes import scene_options, scene_set_option
from viform.cli.app import cli


@cli.command()
@click.option("--out", "out_dir", type=click.Path(), default="viform-demo", show_default=True,
              help="Output folder (report.html, metrics.json, figures/).")
@click.option("--duration", "duration_s", type=float, default=0.04, show_default=True, help="Clip length, s.")
@click.option("--seed", type=int, default=0, show_default=True, help="Noise seed.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of the table.")
@click.option("--json-file", type=click.Path(), default=None, help="Also write the JSON summary here.")
@scene_set_option
def demo(out_dir, duration_s, seed, as_json, json_file, scene_set):
    """One scene that poses the high-speed / high-dynamic-range dilemma, shot by every sensor.

    Writes OUT/report.html (open it in a browser) and OUT/metrics.json, and prints the
    metrics table and which sensor wins on what.
    """
    from viform._validate import check_int, check_positive
    from viform.cli.compare import announce_preparation, check_outputs, command_start, finish

    started = command_start()
    from viform.report.demo import run_demo

    check_int("--seed", seed, 0)
    check_positive("--duration", duration_s)
    check_outputs(out_dir, json_file)
    options = scene_options("dilemma", scene_set)
    announce_preparation()
    doc = run_demo(out_dir, duration_s=duration_s, seed=seed, started_s=started, scene_options=options or None)
    from viform.report.demo import run_demo_sweep

    swept = run_demo_sweep(out_dir, duration_s=duration_s, seed=seed, scene_options=options or None)
    answer = {"report": swept["report"], "demands": swept["answer"]["demands"],
              "demands_explained": swept["demands_explained"],
              "sentences": swept["answer"]["sentences"], "points": swept["n_points"], "seconds": swept["seconds"]}
    finish(doc, out_dir, time.perf_counter() - started, as_json, json_file, extra={"sweep": answer})
    if not as_json:
        click.echo(f"\nWhich setting would meet the scene's demands ({', '.join(answer['demands'])})?")
        for line in answer["demands_explained"]:
            click.echo(f"  {line}")
        click.echo(f"From {answer['points']} settings swept in {answer['seconds']:.0f} s ({answer['report']}):")
        for line in answer["sentences"]:
            click.echo(f"- {line}")
