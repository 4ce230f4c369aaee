"""CLI: ``viform sensors`` — the sensor catalogue; ``viform sensors show NAME`` — one sensor's parameters."""

from __future__ import annotations

import json

import click

from viform._validate import size_text
from viform.cli.app import cli

#: Which part of the model a parameter belongs to, in words (``where`` of a catalogue parameter).
PARTS = {"camera": "camera", "pixel": "pixel", "optics": "optics", "ccd": "CCD", "laser": "laser",
         "receiver": "receiver", "design": "pixel design", "shorthand": "shorthand"}


def catalogue_rows() -> list[dict]:
    from viform.sensors.catalog import SENSORS

    return [{"name": e.name, "family": e.family, "label": e.label, "description": e.description,
             "resolution": list(e.resolution) if e.resolution else None} for e in SENSORS.values()]


def sensor_doc(name: str) -> dict:
    """One sensor as ``viform sensors show`` prints it (JSON form)."""
    from viform.sensors.catalog import entry

    e = entry(name, what="NAME")
    params = [{"name": p.name, "default": p.default, "unit": p.unit, "allowed": p.allowed(),
               "part": PARTS.get(p.where, p.where), "doc": p.doc} for p in e.parameters.values()]
    return {"name": e.name, "family": e.family, "label": e.label, "description": e.description,
            "resolution": list(e.resolution) if e.resolution else None, "scene_shape": list(e.scene_shape),
            "compare_settings": e.compare_settings, "parameters": params}


@cli.command()
@click.argument("words", nargs=-1, metavar="[show NAME]")
@click.option("--json", "as_json", is_flag=True, help="Print the catalogue (or the sensor) as JSON instead of a table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON here.")
def sensors(words, as_json, json_file):
    """Every sensor viform simulates: its name (what every command takes), family and description.

    viform sensors show NAME lists the parameters of sensor NAME with their units, defaults and
    allowed values: what --set NAME=VALUE changes in capture, compare, characterize, dataset,
    gated and highspeed (sweep: --vary).
    """
    from viform._validate import ViformError

    if words and words[0] == "show":
        words = words[1:]
        if len(words) != 1:
            raise ViformError("viform sensors show NAME: give one sensor name (viform sensors lists them)")
    if len(words) > 1:
        raise ViformError(f"give at most one sensor: viform sensors show NAME, not {' '.join(words)!r}")
    doc = sensor_doc(words[0]) if words else catalogue_rows()
    if json_file:
        from viform._io import write_json

        write_json(json_file, doc)
    if as_json:
        click.echo(json.dumps(doc, indent=2))
    elif words:
        _print_sensor(doc)
    else:
        _print_catalogue(doc)


def _print_catalogue(rows) -> None:
    w = max(len(r["name"]) for r in rows)
    f = max(len(r["family"]) for r in rows)
    click.echo(f"{'name':<{w}}  {'family':<{f}}  description")
    for r in rows:
        click.echo(f"{r['name']:<{w}}  {r['family']:<{f}}  {r['description']}")
    click.echo("\nviform sensors show NAME: its parameters (units, defaults, allowed values).")


def _print_sensor(doc) -> None:
    from viform.sensors.parameters import value_text

    size = size_text(*doc["resolution"], "px (width × height)") if doc["resolution"] else "the scene's"
    click.echo(f"{doc['name']}: {doc['description']}")
    click.echo(f"family {doc['family']}; pixel array {size}")
    if doc["compare_settings"]:
        click.echo("compare and sweep shoot it with "
                   + ", ".join(f"{k} = {v}" for k, v in doc["compare_settings"].items()))
    rows = [(p["name"], value_text(p["default"]), p["unit"], p["allowed"], p["part"], p["doc"])
            for p in doc["parameters"]]
    head = ("parameter", "default", "unit", "allowed", "part", "")
    widths = [max(len(str(r[i])) for r in [head, *rows]) for i in range(5)]
    click.echo("  ".join(f"{h:<{w}}" for h, w in zip(head, widths, strict=False)).rstrip())
    for r in rows:
        click.echo(("  ".join(f"{str(v):<{w}}" for v, w in zip(r, widths, strict=False)) + "  " + r[5]).rstrip())
    click.echo(f"\nset one with --set NAME=VALUE (capture, characterize, dataset, gated, highspeed), "
               f"--set {doc['name']}:NAME=VALUE (compare) or --vary {doc['name']}:NAME=VALUES (sweep).")


