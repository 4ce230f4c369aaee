"""Fuzzing every numeric option of every command (found at run time, so new commands are covered).

Parse level (all commands): non-finite, huge, overflowing and non-numeric values must be
refused at parse time: exit 2, one line naming the flag the user typed, no traceback.
Run level (the quick commands, from a small valid invocation): boundary values (0, −1, huge,
tiny) must give exit 0 or exit 2 with one line, within a time limit, and leave no temporary
file behind.

A bigger campaign (every command, each run in its own process with a time limit)::

    python tests/cli/test_fuzz_options.py --campaign --timeout 60
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import click
import numpy as np
import pytest

from viform.cli import _load_commands, main
from viform.cli._types import flag_of, walk
from viform.cli.app import cli

#: Values every numeric option must refuse at parse time (so no command starts any work).
PARSE_VALUES = ["nan", "inf", "-inf", "1e308", "-1e308", "9223372036854775808", "1e400", "abc", "", "NaN",
                "-9e99"]
RUN_VALUES = ["0", "-1", "1e12", "-1e12", "2147483648", "1e-300"]
#: Work caps while fuzzing (the documented environment variables): big requests are refused, not run.
FUZZ_ENV = {"VIFORM_MAX_PIXEL_TICKS": "1e7", "VIFORM_MAX_PIXELS": "65536"}


def numeric_options():
    _load_commands()
    for command in walk(cli):
        for param in command.params:
            if isinstance(param, click.Option) and param.type.name in ("float", "integer"):
                yield command.name, flag_of(param), param.type.name


def run_inprocess(args):
    err, out = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        rc = main(args)
    return rc, err.getvalue()


def test_every_numeric_option_is_bounded_at_parse_time():
    options = list(numeric_options())
    assert len(options) > 40  # every command's options were found
    failures = []
    for command, flag, kind in options:
        values = PARSE_VALUES + (["1.5", "2147483649"] if kind == "integer" else [])
        for value in values:
            rc, err = run_inprocess([command, flag, value])
            lines = [line for line in err.splitlines() if line.strip() and not line.startswith("compiling ")]
            if rc != 2 or len(lines) != 1 or flag not in err or "Traceback" in err:
                failures.append((command, flag, value, rc, err.strip()[:200]))
    assert failures == [], failures[:10]


def base_invocations(folder: Path) -> dict[str, list[str]]:
    """Small valid invocations of the quick commands (inputs written into ``folder``)."""
    from viform.coding.aer_file import encode_source
    from viform.stream.container import SpikeStream
    from viform.stream.io import save_spikes

    stream = SpikeStream(np.random.default_rng(0).random((80, 8, 16)) < 0.2, 40_000.0, 60.0)
    dat = save_spikes(folder / "in.dat", stream)
    vfc = folder / "in.vfc"
    encode_source(stream, vfc, "strict")
    out = folder / "out"
    return {
        "simulate": ["simulate", "translating", "--duration", "0.001", "--height", "8", "--width", "16",
                     "--out", str(out / "x.dat")],
        "reconstruct": ["reconstruct", str(dat), "--method", "interval", "--at", "0.001", "--out", str(out / "r.png")],
        "info": ["info", str(dat)],
        "verify": ["verify", str(dat)],
        "encode": ["encode", str(dat), str(out / "e.vfc")],
        "decode": ["decode", str(vfc), str(out / "d.npz")],
        "dr": ["dr"],
    }


def _with(args, flag, value):
    args = list(args)
    if flag in args:
        args[args.index(flag) + 1] = value
    else:
        args += [flag, value]
    return args


def classify(rc, err):
    lines = [line for line in err.splitlines() if line.strip() and "%|" not in line and "/s]" not in line
             and not line.startswith("compiling ")]  # the first-run compile notice is not an error line
    if rc == "hang":
        return "hang"
    if rc == 0:
        return "ok"
    if rc == 2:
        return "refused" if len(lines) == 1 and "Traceback" not in err and "internal error" not in err \
            else "multiline"
    if rc == 1 or "internal error" in err:
        return "internal"
    return "crash"


@pytest.mark.parametrize("command", ["simulate", "reconstruct", "info", "encode", "decode", "dr"])
def test_boundary_values_fail_cleanly_or_run(tmp_path, monkeypatch, command):
    """(simulate keeps only the values it must refuse: its first run compiles the kernel, which is slow.)"""
    for name, value in FUZZ_ENV.items():
        monkeypatch.setenv(name, value)
    base = base_invocations(tmp_path)[command]
    options = [flag for name, flag, _ in numeric_options() if name == command]
    failures = []
    for flag in options:
        for value in RUN_VALUES:
            if command == "simulate" and value != "-1e12":
                continue
            (tmp_path / "out").mkdir(exist_ok=True)
            rc, err = run_inprocess(_with(base, flag, value))
            kind = classify(rc, err)
            left = [p.name for p in tmp_path.rglob("*") if ".viform-" in p.name]
            if kind not in ("ok", "refused") or left:
                failures.append((flag, value, rc, err.strip()[:200], left))
    assert failures == [], failures[:10]


def test_options_that_crashed_or_hung_are_refused_in_one_line(tmp_path):
    """Issue 26.5: each was a traceback, a worker's traceback or minutes of silent work."""
    from viform.stream.container import SpikeStream
    from viform.stream.io import save_spikes

    dat = save_spikes(tmp_path / "x.dat", SpikeStream(np.random.default_rng(0).random((80, 8, 16)) < 0.2,
                                                      40_000.0, 60.0))
    clips = tmp_path / "src" / "clip1"
    clips.mkdir(parents=True)
    for k in range(2):
        np.save(clips / f"{k}.npy", np.zeros((8, 16)))  # not read: the options are refused first
    cases = {
        "--fps": ["reconstruct", str(dat), "--method", "accumulation", "--every", "20", "--out",
                  str(tmp_path / "r"), "--video", str(tmp_path / "v.gif"), "--fps", "1e-300"],
        "--max-lux": ["dataset", str(tmp_path / "src"), "--out", str(tmp_path / "ds"), "--height", "8", "--width",
                      "16", "--workers", "1", "--frame-rate-hz", "1000", "--max-lux", "2147483648"],
        "--frame-rate-hz": ["dataset", str(tmp_path / "src"), "--out", str(tmp_path / "ds"), "--height", "8",
                            "--width", "16", "--workers", "1", "--frame-rate-hz", "1e-300"],
        "--force": ["simulate", "translating", "--height", "32", "--width", "48", "--duration", "0.005",
                    "--out", str(tmp_path / "s.dat"), "--clock-hz", "2147483648"],
    }
    for flag, args in cases.items():  # refused before any work (the hang was the failure)
        rc, err = run_inprocess(args)
        assert classify(rc, err) == "refused" and flag in err, (args, rc, err)
    left = sorted(p.name for p in tmp_path.rglob("*") if p.name not in ("x.dat", "x.dat.json", "src", "clip1")
                  and p.suffix != ".npy")
    assert left == []


# ---------------------------------------------------------------- campaign (outside the suite)
def campaign(timeout_s: float, values=None) -> dict:
    """Every numeric option of every command, from each command's default invocation, in-process
    with a time limit per run (work caps of :data:`FUZZ_ENV`)."""
    import shutil

    from test_fuzz_files import run_command

    os.environ.update(FUZZ_ENV)
    values = values or PARSE_VALUES + ["0", "-1", "-1e12", "2147483648", "1e-300"]
    counts, examples = {}, {}
    with tempfile.TemporaryDirectory(prefix="viform-optfuzz-") as work:
        work = Path(work)
        bases = base_invocations(work)
        for command, flag, _ in list(numeric_options()):
            base = bases.get(command, [command, "--out", str(work / "out" / command)])
            for value in values:
                (work / "out").mkdir(exist_ok=True)
                args = _with(base, flag, value)
                result = run_command(args, timeout_s)
                kind = classify(result["rc"], result["err"])
                left = [str(p) for p in work.rglob("*") if ".viform-" in p.name]
                if left:
                    counts["temp-left"] = counts.get("temp-left", 0) + 1
                counts[kind] = counts.get(kind, 0) + 1
                if kind not in ("ok", "refused"):
                    examples.setdefault(kind, []).append([command, flag, value, str(result["rc"]),
                                                          result["err"].strip()[-300:]])
                print(f"{kind:9s} {result['s']:6.1f}s {command} {flag} {value}", file=sys.stderr, flush=True)
                shutil.rmtree(work / "out", ignore_errors=True)
    return {"counts": counts, "examples": examples}


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    parser = argparse.ArgumentParser()
    parser.add_argument("--campaign", action="store_true")
    parser.add_argument("--timeout", type=float, default=120.0)
    a = parser.parse_args()
    started = time.perf_counter()
    result = campaign(a.timeout)
    result["elapsed_s"] = round(time.perf_counter() - started, 1)
    print(json.dumps(result, indent=1))
