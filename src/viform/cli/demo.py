"""CLI: ``viform demo`` — the main job on the built-in default scene."""

from __future__ import annotations

import json

import click

from viform.cli.app import cli


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
