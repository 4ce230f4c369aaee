"""CLI: ``viform info`` (what a spike file or coded file holds) and ``viform verify`` (is it whole)."""

from __future__ import annotations

import json
import warnings

import click

from viform._validate import UnverifiedDataWarning
from viform.cli._common import apply_options, spike_file_options
from viform.cli._common import open_source as _open
from viform.cli.app import cli

#: Units shown after the values of ``info`` (by the summary's key).
_UNITS = {"clock_hz": "Hz", "duration_s": "s", "start_time_s": "s", "threshold_electrons": "e⁻",
          "spikes_per_s": "spikes/s", "mean_firing_rate_hz": "Hz", "raw_data_rate_bit_per_s": "bit/s",
          "raw_data_rate_mb_per_s": "MB/s", "mean_firing_rate_per_tick": "per tick",
          "dark_current_e_per_s": "e⁻/s", "bytes": "bytes"}

_json_options = [
    click.option("--json", "as_json", is_flag=True, help="Print the result as JSON instead of the table."),
    click.option("--json-file", type=click.Path(dir_okay=False), default=None,
                 help="Also write the JSON that --json prints to this file."),
]


def _emit_json(result: dict, as_json: bool, json_file) -> bool:
    """``--json-file`` gets the same JSON as ``--json``; True when the table is not wanted."""
    if json_file is not None:
        from viform._io import write_json

        write_json(json_file, json.loads(json.dumps(result, default=str)))
    if as_json:
        click.echo(json.dumps(result, indent=2, default=str))
    return as_json


def _coded_module():
    try:
        from viform.coding import aer_file
    except ImportError:
        return None
    return aer_file


def _not_coded(file, is_coded) -> None:
    """A ``.vfc`` that does not start with the coded-file magic number: say so (not "unknown type")."""
    from pathlib import Path

    from viform._validate import ViformError

    if Path(file).suffix.lower() == ".vfc" and (is_coded is None or not is_coded(file)):
        size = Path(file).stat().st_size if Path(file).is_file() else None
        what = "is empty" if size == 0 else "is a folder" if size is None else \
            "does not start with the coded-file marker (damaged, or another format named .vfc)"
        raise ViformError(f"FILE {str(file)!r} is not a readable coded spike file: it {what}")


def _coded_file_summary(file):
    """The first-spike coding module's description of a coded file, if FILE is one."""
    aer_file = _coded_module()
    if aer_file is None:
        return None
    _not_coded(file, getattr(aer_file, "is_coded_file", None))
    describe = getattr(aer_file, "describe_coded_file", None)
    is_coded = getattr(aer_file, "is_coded_file", None)
    if describe is None or is_coded is None or not is_coded(file):
        return None
    return describe(file)


def _verify_coded(file) -> dict | None:
    """Full check of a coded file through the coding module (None when FILE is not one)."""
    aer_file = _coded_module()
    if aer_file is None:
        return None
    is_coded = getattr(aer_file, "is_coded_file", None)
    _not_coded(file, is_coded)
    if is_coded is None or not is_coded(file):
        return None
    verify = getattr(aer_file, "verify_coded_file", None)
    if verify is not None:
        result = verify(file)
        if isinstance(result, dict):
            return {"file": str(file), "format": "vfc", "verified": True, **result}
    coded = aer_file.CodedFile(file)
    spikes = coded.verify()  # decodes every segment, checking each one's checksum
    return {"file": str(file), "format": "vfc", "verified": True,
            "checks": [f"every segment decoded and checked ({spikes} spikes)"]}


def _fmt(key: str, value) -> str:
    unit = _UNITS.get(key, "")
    if isinstance(value, bool) or value is None:
        text = {True: "yes", False: "no", None: "unknown"}[value]
    elif isinstance(value, float):
        text = f"{value:,.0f}" if value.is_integer() and 1e4 <= abs(value) < 1e9 else f"{value:.4g}"
    elif isinstance(value, int):
        text = f"{value:,}"
    else:
        text = str(value)
    return f"{text} {unit}".rstrip() if value is not None else text


def _label(key: str) -> str:
    """``clock_hz`` → ``clock`` (the unit goes after the value)."""
    if key in _UNITS:
        for suffix in ("_bit_per_s", "_mb_per_s", "_e_per_s", "_per_s", "_per_tick", "_hz", "_s", "_electrons"):
            if key.endswith(suffix):
                key = key[: -len(suffix)] + ("_rate" if suffix.endswith("per_s") and "rate" not in key else "")
                break
    return key.replace("_", " ")


#: Quantities given in two units: one row each, named once, the second unit in brackets
#: (``mean firing rate: 0.15 per tick (6027 Hz)``), and their own names (not "spikes rate").
_PAIRS = {"mean_firing_rate_per_tick": "mean_firing_rate_hz", "raw_data_rate_mb_per_s": "raw_data_rate_bit_per_s"}
_NAMES = {"spikes_per_s": "spikes per second", "spike_count": "spikes",
          "mean_firing_rate_per_tick": "mean firing rate, per pixel",
          "raw_data_rate_mb_per_s": "raw data rate"}


def _table_rows(summary: dict) -> list[tuple[str, str]]:
    """(label, value with unit) of every field, each quantity once."""
    rows = []
    seconds = set(_PAIRS.values())
    for key, value in summary.items():
        if key in seconds and any(k in summary for k, v in _PAIRS.items() if v == key):
            continue  # shown in brackets beside its pair
        if isinstance(value, (dict, list)):
            value = json.dumps(value, default=str)
            value = value if len(value) <= 100 else value[:99] + "…"
        text = _fmt(key, value)
        if key in _PAIRS and _PAIRS[key] in summary:
            text += f" ({_fmt(_PAIRS[key], summary[_PAIRS[key]])})"
        rows.append((_NAMES.get(key, _label(key)), text))
    return rows


def _table(summary: dict) -> None:
    rows = _table_rows(summary)
    width = max(len(label) for label, _ in rows)
    for label, text in rows:
        click.echo(f"{label:>{width}}: {text}")


@cli.command()
@click.argument("file", type=click.Path(exists=True))
@apply_options(_json_options)
@spike_file_options(partial=True)
def info(file, as_json, json_file, height, width, no_flip, clock_hz, key, axes, allow_partial):
    """Resolution, duration, ticks, spike count, firing and data rates of a spike stream (or a coded file).

    Reading the stream checks it: zarr chunk checksums, the .npz zip checksums, a .dat
    file's size and checksum against its sidecar. The last line says what was verified.
    """
    summary = _coded_file_summary(file)
    if summary is None:
        source = _open(file, height, width, clock_hz, flip=not no_flip, allow_partial=allow_partial, axes=axes,
                       key=key)
        with warnings.catch_warnings():  # the table's "verified" row says it
            warnings.simplefilter("ignore", UnverifiedDataWarning)
            summary = {"file": str(file), "format": source.metadata.get("format"), **source.summary()}
        meta = source.metadata
        for field in ("scene", "seed", "viform_version", "utc_date"):
            if meta.get(field) is not None:
                summary[field] = meta[field].get("name", meta[field]) if isinstance(meta[field], dict) else meta[field]
        summary.update(_verification(source))
    else:
        # info does not decode the segments: a header edited with its CRC recomputed (another width, another
        # mode) passes every checksum and only a decode shows it, so only verify says "verified"
        summary = dict(summary)
        checked = summary.get("verification") if summary.get("verified") else None
        summary["verified"] = False
        summary["verification"] = ("header, end record and segment checksums match, but the segments are not "
                                   "decoded here: run viform verify" if checked
                                   else "segments not decoded here: run viform verify")
    if _emit_json(summary, as_json, json_file):
        return
    _table(summary)


def _verification(source) -> dict:
    """What reading the stream checked (summary() has read every tick)."""
    fmt = source.metadata.get("format")
    if fmt == "zarr":
        if getattr(source, "checked", False):
            return {"verified": True, "verification": "header and every chunk's CRC-32 checked"}
        return {"verified": False, "verification": "store written without checksums (older viform)"}
    if fmt == "npz":
        if getattr(source, "_blocks", None) is not None:
            return {"verified": True, "verification": "header checksum, block CRC-32s and zip CRC-32 of the spike "
                                                      "array checked; values are 0/1"}
        return {"verified": False, "verification": "no viform checksums (another tool's .npz, or viform's header "
                                                   "removed): read unverified; values are 0/1"}
    if fmt == "dat":
        if getattr(source, "sidecar", None) is None:
            return {"verified": False, "verification": "no sidecar: nothing to check the file against"}
        result = source.verify()
        return {"verified": result["verified"], "verification": "; ".join(result["checks"])}
    return {"verified": False, "verification": "not checked"}


@cli.command()
@click.argument("file", type=click.Path(exists=True))
@apply_options(_json_options)
@spike_file_options(partial=True)
def verify(file, as_json, json_file, height, width, no_flip, clock_hz, key, axes, allow_partial):
    """Check that FILE (.dat with its sidecar, .npz, .zarr or .vfc) is whole and consistent.

    Reads everything: a .dat against the size, BLAKE2b and block CRC-32s in its sidecar, a .npz
    against the block CRC-32s in its header and every member's zip checksum, every chunk of a
    zarr store against its checksum manifest, every segment of a .vfc.

    \b
    Exit status:
      0  whole: every byte checked against the checksums viform wrote
      2  damaged, edited or unreadable (one line on stderr names what)
      3  readable, but not verifiable: the file carries no viform checksums (another
         tool's file, a .dat without its sidecar, or a file whose checksums were removed)
    """
    from viform.stream.io import verify_spikes

    result = _verify_coded(file)
    if result is None:
        with warnings.catch_warnings():  # the result says whether it was verified
            warnings.simplefilter("ignore", UnverifiedDataWarning)
            result = verify_spikes(file, height=height, width=width, clock_hz=clock_hz,
                                   allow_partial=allow_partial, key=key, axes=axes,
                                   flip=None if not no_flip else False)
    if not _emit_json(result, as_json, json_file):
        if result["verified"]:
            click.echo(f"{file}: OK ({'; '.join(result['checks'])})")
        else:
            click.echo(f"{file}: readable, but not verified: {'; '.join(result['checks'])}")
    if not result["verified"]:
        from viform.cli import ExitStatus

        raise ExitStatus(UNVERIFIED_EXIT)


#: Exit status of ``verify`` for a file that is readable but carries no viform checksums.
UNVERIFIED_EXIT = 3

