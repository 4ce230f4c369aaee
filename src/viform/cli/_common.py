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


def spike_file_options(*, partial: bool = False):
    """Decorator: the options of every command that reads a spike file, declared once.

    ``--height``/``--width``/``--no-flip`` describe a ``.dat`` without a sidecar (or with rows
    stored upright), ``--clock-hz`` a file that does not record its clock, ``--key``/``--axes``
    a ``.npz`` written by another tool (e.g. SpikingSIM's ``arr_0`` in rows × columns × ticks
    order: ``--key arr_0 --axes hwt``); ``partial`` adds ``--allow-partial``. The command
    receives ``height, width, clock_hz, no_flip, key, axes`` (and ``allow_partial``) and hands
    them to :func:`open_source`; errors of the readers then name these flags.
    """
    options = [
        click.option("--height", type=int, default=None, help="Rows of a .dat file without a sidecar."),
        click.option("--width", type=int, default=None, help="Columns of a .dat file without a sidecar."),
        click.option("--no-flip", is_flag=True,
                     help=".dat rows stored top row first (some simulators; the cameras store them bottom-up)."),
        click.option("--clock-hz", type=float, default=None,
                     help="Readout clock, Hz, of a file that does not record it (default 40 kHz)."),
        click.option("--key", default=None,
                     help="Array name in a .npz (default: spk, then spikes; SpikingSIM writes arr_0)."),
        click.option("--axes", default=None,
                     help="Axis order of a .npz array that does not declare it: thw (ticks, rows, columns) "
                          "or hwt (rows, columns, ticks)."),
    ]
    if partial:
        options.append(click.option("--allow-partial", is_flag=True,
                                    help="Keep the whole frames of a .dat with trailing bytes."))

    def decorate(f):
        for option in reversed(options):
            f = option(f)
        return f

    return decorate


def announce_connection(scheduler: str, timeout_s: float) -> None:
    """Say, before the wait, that a command is reaching a dask scheduler and for how long it tries."""
    click.echo(f"connecting to the dask scheduler at {scheduler} (trying for up to {timeout_s:g} s: "
               "--connect-timeout) …", err=True)


def report(as_json: bool, line: str, summary: dict) -> None:
    click.echo(json.dumps(summary, indent=2) if as_json else line)
