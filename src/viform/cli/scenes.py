"""CLI: ``viform scenes`` — every scene of the catalogue with its parameters; ``scenes show NAME`` prints
its description, a starting point for one's own."""

from __future__ import annotations

import json

import click

from viform._io import JSON_FILE_HELP
from viform._validate import ViformError
from viform.cli.app import cli


@cli.group(invoke_without_command=True)
@click.option("--json", "as_json", is_flag=True, help="Print the catalogue as JSON.")
@click.option("--json-file", type=click.Path(), default=None, help=JSON_FILE_HELP)
@click.pass_context
def scenes(ctx, as_json, json_file):
    """List every scene viform knows by name: what it is, its parameters and defaults, and whether a
    description of it ships (print it with 'viform scenes show NAME') or why it stays code.

    Any command that takes SCENE also takes a scene description file (YAML or JSON; format in
    docs/scenes.md) and --scene-set NAME=VALUE,... for the parameters listed here.
    """
    if ctx.invoked_subcommand is not None:
        return
    from viform._io import check_json_file, write_json
    from viform.light.catalog import SCENES

    check_json_file(json_file)
    from viform.light.description import UNIVERSAL_SETTINGS

    rows = []
    for entry in SCENES.values():
        rows.append({"name": entry.name, "summary": entry.summary,
                     "parameters": {k: _plain(v) for k, v in entry.parameters.items()},
                     "settings": sorted(UNIVERSAL_SETTINGS),
                     "description": entry.description, "described_as": entry.described_as,
                     "code": entry.code_reason})
    if json_file is not None:
        write_json(json_file, rows)
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    for row in rows:
        click.echo(f"{row['name']}: {row['summary']}")
        kind = (f"  description: yes (viform scenes show {row['name']}); {row['described_as']}"
                if row["description"] else f"  description: no — {row['code']}")
        click.echo(kind)
        params = ", ".join(f"{k}={json.dumps(v)}" for k, v in row["parameters"].items())
        click.echo(f"  parameters: {params or 'none'}; and {', '.join(row['settings'])}")
    click.echo("\nA scene description (.yaml/.json) is a SCENE too: see docs/scenes.md and examples/scenes/.")


def _plain(value):
    if isinstance(value, tuple):
        return list(value)
    return value if isinstance(value, (int, float, str, bool, list, dict, type(None))) else repr(value)


@scenes.command("show")
@click.argument("name")
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON instead of YAML.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help=JSON_FILE_HELP)
def show(name, as_json, json_file):
    """Print the description of scene NAME (YAML), to copy and change."""
    from viform._io import check_json_file, write_json
    from viform.light.catalog import SCENES

    check_json_file(json_file)
    entry = SCENES.get(name)
    if entry is None:
        raise ViformError(f"NAME = {name!r} is not allowed: choose one of {', '.join(SCENES)}")
    if entry.description is None:
        raise ViformError(f"scene {name!r} ships no description: {entry.code_reason}; 'viform scenes show "
                          f"{next(n for n, e in SCENES.items() if e.description)}' prints one to start from")
    text = entry.description_path().read_text(encoding="utf-8")
    if as_json or json_file is not None:
        import yaml

        data = yaml.safe_load(text)
        if json_file is not None:
            write_json(json_file, data)
        if as_json:
            click.echo(json.dumps(data, indent=2))
            return
    click.echo(text, nl=False)
