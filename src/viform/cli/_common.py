"""Helpers shared by the CLI command modules (instants, opening spike files, reports)."""

from __future__ import annotations

import json

import click

from viform._validate import ViformError


def apply_options(options):
    """A decorator that adds a list of click options to a command, in the order listed."""
    def decorator(f):
        for option in reversed(options):
            f = option(f)
        return f

    return decorator


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


def quote_names(message: str, names) -> str:
    """``message`` with each of ``names`` quoted where it stands as a word (the CLI would otherwise
    read a parameter such as frame_rate_hz as one of its own flags and name that flag)."""
    import re

    for name in sorted(names, key=len, reverse=True):
        message = re.sub(rf"(?<![\w'\"./-]){re.escape(name)}(?![\w'\"-])", f"'{name}'", message)
    return message


def parse_settings(entry, items, flag: str = "--set", skip_build: bool = False) -> dict:
    """``NAME=VALUE`` texts → {parameter: value} of the catalogue sensor ``entry``, validated.

    Errors name the flag, the parameter, its unit and what is allowed; the values are then
    checked together by building the sensor (a limit across parameters, e.g. an exposure
    within the frame period), unless ``skip_build``.
    """
    out = {}
    params = entry.parameters
    for item in items or ():
        name, sep, text = str(item).partition("=")
        name = name.strip()
        if not sep or not name:
            raise ViformError(f"{flag} {item!r} is not allowed: give NAME=VALUE, e.g. {flag} "
                              f"{next(iter(params))}=VALUE (viform sensors show {entry.name} lists the names)")
        if name not in params:
            raise ViformError(f"{flag} {item!r} is not allowed: {name!r} is not a parameter of {entry.name}; give "
                              f"NAME=VALUE with NAME one of {', '.join(repr(n) for n in params)} (viform sensors "
                              f"show {entry.name})")
        if name in out:
            raise ViformError(f"{flag} {item!r}: {name!r} is already set by another {flag}")
        try:
            out[name] = params[name].parse(text)
        except ViformError as exc:
            raise ViformError(f"{flag} {item!r}: {quote_names(str(exc), params)}") from None
    if out and not skip_build:
        try:
            entry.build(**out)
        except ViformError as exc:
            raise ViformError(f"{flag}: {quote_names(str(exc), params)}") from None
    return out


def sensor_names_text(spec: str = "") -> str:
    """Names of the catalogue's sensors (of the comma-separated families in ``spec``), for help texts."""
    from viform.sensors.catalog import sensor_names

    return ", ".join(sensor_names(*[f for f in spec.split(",") if f]))


def _fill_sensors(text):
    """``{sensors}`` / ``{sensors:FAMILY,...}`` in a help text → the catalogue's names."""
    import re

    if not text or "{sensors" not in text:
        return text
    return re.sub(r"\{sensors(?::([\w,]+))?\}", lambda m: sensor_names_text(m.group(1) or ""), text)


class CatalogHelp(click.Command):
    """A command whose help lists sensors from the catalogue (:mod:`viform.sensors.catalog`), read when
    the help is shown (the catalogue loads the simulators: not at every start of the CLI)."""

    def format_help(self, ctx, formatter):
        saved = self.help, [(p, getattr(p, "help", None)) for p in self.params]
        self.help = _fill_sensors(self.help)
        for p, text in saved[1]:
            if text is not None:
                p.help = _fill_sensors(text)
        try:
            super().format_help(ctx, formatter)
        finally:
            self.help = saved[0]
            for p, text in saved[1]:
                if text is not None:
                    p.help = text
