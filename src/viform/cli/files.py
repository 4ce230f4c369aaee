"""CLI: ``viform info`` — what a spike file or coded file holds."""

from __future__ import annotations

import json

import click

from viform.cli._common import open_source as _open
from viform.cli.app import cli


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
