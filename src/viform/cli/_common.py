"""Helpers shared by the CLI command modules (instants, opening spike files, reports)."""

from __future__ import annotations

import json

import click

from viform._validate import ViformError


def parse_times(text: str) -> list[float]:
    try:
        times = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise ViformError(f"--at = {text!r} is not allowed: give instants in seconds, e.g. --at 0.01,0.02") from None
    if not times:
        raise ViformError("--at is empty: give at least one instant in seconds")
    return times


def open_source(path, height, width, clock_hz=None, flip=True, allow_partial=False, axes=None, key=None):
    """Open a spike file for a command; ``flip=True`` (no ``--no-flip``) lets a sidecar decide the row order."""
    from viform.stream.io import open_spikes

    return open_spikes(path, height, width, clock_hz=clock_hz, flip=None if flip else False,
                       allow_partial=allow_partial, axes=axes, key=key)


def report(as_json: bool, line: str, summary: dict) -> None:
    click.echo(json.dumps(summary, indent=2) if as_json else line)
