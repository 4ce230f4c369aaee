"""Fuzzing the readers through the CLI: damaged and forged .dat/.npz/.zarr/.vfc files.

Each case copies a small good file, damages it one way (bit flips, truncation, appended
bytes, a deleted chunk or sidecar, a forged header field with its checksum recomputed, a
forged array shape, checksum fields deleted, a version edited down) and runs ``info``,
``verify``, ``reconstruct`` (partial reads: an early and a later instant, each method in
turn), ``encode`` or ``decode`` on it, in a worker process, each command under a time limit.
Every outcome must be either exit 0 with the same result as the undamaged file (the images
of ``reconstruct`` are compared with the intact file's, value for value), or exit 2 with one
line on stderr, no traceback and nothing left behind. Counted as failures: internal errors
(exit 1), crashes, hangs, silent wrong outputs (exit 0 though the result differs from the
intact file's), temporary files left, and peak memory above 1 GB.

Formats: viform's ``.dat`` + sidecar, ``.npz``, zarr and ``.vfc``, and a Spike-Zoo style
``.npz`` of another tool (``zoo``: no viform header, compressed). viform's block checksums
are made small here (:data:`FUZZ_BLOCK_BYTES`) so that the tiny files have many blocks and a
partial read touches only some of them, as a real file's does.

Run a bigger campaign (outside the suite) with::

    python tests/cli/test_fuzz_files.py --cases 2000 --seed 1
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

FORMATS = ("dat", "npz", "zarr", "vfc", "zoo")
METHODS = ("accumulation", "interval", "multi-interval", "motion")
#: Block size of viform's per-block checksums in the campaign (1 MiB in real files).
FUZZ_BLOCK_BYTES = 512
FORGED_VALUES = [-1, 0, 0.5, 1e308, -1e308, 2**63, 1e12, 65537, "nan", "x", None, [], {}, True,
                 float("nan"), float("inf")]
COMMAND_TIMEOUT_S = 20.0


class Hang(BaseException):
    """A command ran past its time limit."""


# ---------------------------------------------------------------- originals
def make_originals(folder: Path) -> dict:
    from viform.coding.aer_file import encode_source
    from viform.sensors.spike import SpikeSensor
    from viform.stream.container import SpikeStream
    from viform.stream.io import save_spikes

    rng = np.random.default_rng(0)
    meta = {"sensor": SpikeSensor(threshold_electrons=60.0).describe(), "scene": {"name": "fuzz"}, "seed": 1}
    stream = SpikeStream(rng.random((160, 8, 16)) < 0.2, 40_000.0, 60.0, 0.0, meta)
    paths = {}
    for fmt in ("dat", "npz", "zarr"):
        paths[fmt] = save_spikes(folder / f"orig.{fmt}", stream, block_ticks=32)
    paths["vfc"] = folder / "orig.vfc"
    encode_source(stream, paths["vfc"], "strict", segment_ticks=64)
    paths["zoo"] = folder / "zoo.npz"  # another tool's layout: Spike-Zoo's key and scalars, compressed
    np.savez_compressed(paths["zoo"], spk=stream.spikes.astype(np.uint8), clock_hz=np.float64(40_000.0))
    return paths


def fingerprint(path: Path) -> str | None:
    """What a reader gets from the file (bits and the fields that change results), or None if refused."""
    from viform._validate import ViformError
    from viform.stream.io import open_spikes

    try:
        if path.suffix == ".vfc":
            from viform.coding.aer_file import CodedFile

            source = CodedFile(path)
        else:
            source = open_spikes(path)
        h = hashlib.blake2b(digest_size=16)
        for _, block in source.iter_blocks(64):
            h.update(np.packbits(block).tobytes())
        sensor = (source.metadata or {}).get("sensor") or {}
        fields = [source.shape, source.clock_hz, source.threshold_electrons, source.start_time_s,
                  json.dumps(sensor.get("optics"), sort_keys=True), sensor.get("dark_current_e_per_s")]
        h.update(repr(fields).encode())
        return h.hexdigest()
    except ViformError:
        return None
    except Exception as exc:  # a reader failing otherwise is itself a finding
        return f"error:{type(exc).__name__}"


# ---------------------------------------------------------------- mutations
def _files_of(path: Path) -> list[Path]:
    if path.is_dir():
        return sorted(p for p in path.rglob("*") if p.is_file())
    side = path.with_name(path.name + ".json")
    return [path] + ([side] if side.exists() else [])


def _forge_json(rng, header: dict) -> str:
    key = str(rng.choice(sorted(header)))
    value = FORGED_VALUES[rng.integers(len(FORGED_VALUES))]
    if rng.random() < 0.2:
        header.pop(key)
        return f"drop {key}"
    header[key] = value
    return f"{key}={value!r}"


def mutate(rng, fmt: str, original: Path, folder: Path) -> tuple[Path, str]:
    """Copy ``original`` into ``folder`` and damage the copy one way; returns (path, description)."""
    from viform.stream import sidecar, zarr_store

    path = folder / original.name
    if original.is_dir():
        shutil.copytree(original, path)
    else:
        shutil.copy(original, path)
        side = sidecar.sidecar_path(original)
        if side.exists():
            shutil.copy(side, sidecar.sidecar_path(path))
    files = _files_of(path)
    kind = rng.choice(["flip", "flip", "truncate", "append", "delete", "forge", "forge", "shape", "unmark",
                       "late"])
    target = files[rng.integers(len(files))]
    if kind == "late":  # damage past the instants read early: only per-block checks catch it in a partial read
        what = _unmark(rng, fmt, path) + "; " if rng.random() < 0.5 and fmt in ("dat", "zarr", "npz") else ""
        target = max(_files_of(path), key=lambda p: p.stat().st_size)
        data = bytearray(target.read_bytes())
        i = int(rng.integers(len(data) // 2, len(data)))
        data[i] ^= 1 << int(rng.integers(8))
        target.write_bytes(bytes(data))
        return path, f"{what}flip a bit of byte {i} of {target.relative_to(folder)}"
    if kind == "unmark" and fmt in ("dat", "zarr", "npz"):
        # the checks switched off by a plain edit: checksum fields deleted, the version edited down
        return path, _unmark(rng, fmt, path)
    if kind == "forge" and fmt in ("dat", "zarr", "npz"):
        if fmt == "dat":
            side = sidecar.sidecar_path(path)
            header = json.loads(side.read_text())
            what = _forge_json(rng, header)
            header[sidecar.DIGEST_KEY] = sidecar._digest(header)
            side.write_text(json.dumps(header))
        elif fmt == "zarr":
            meta_file = path / "zarr.json"
            meta = json.loads(meta_file.read_text())
            what = _forge_json(rng, meta["attributes"]["viform"])
            meta["attributes"]["viform"]["header_blake2b"] = zarr_store._header_digest(meta["attributes"]["viform"])
            meta_file.write_text(json.dumps(meta))
        else:
            from viform.stream.checksums import header_digest

            with np.load(path) as data:
                members = {k: data[k] for k in data.files}
            if "viform_header" not in members:  # another tool's scalars: absurd values must be refused
                values = [-1.0, 0.0, 1e-300, 1e308, np.nan, np.inf, True, np.array([1.0, 2.0]), 1e-300]
                value = values[rng.integers(len(values))]
                name = ["clock_hz", "threshold_electrons", "start_time_s"][rng.integers(3)]
                members[name] = np.asarray(value)
                what = f"{name}={value!r}"
            else:
                header = json.loads(str(members["viform_header"]))
                what = _forge_json(rng, header)
                header["header_blake2b"] = header_digest(header)
                members["viform_header"] = np.array(json.dumps(header))
            with open(path, "wb") as f:
                np.savez(f, **members)
        return path, f"forge {what}"
    if kind == "shape" and fmt in ("npz", "zoo"):
        shape = [(2000, 1000, 1000), (16, 8, 160), (160, 16, 8), (80, 8, 32), (0, 8, 16), (160, 8, 16, 1)][
            rng.integers(6)]
        with np.load(path) as data:
            spk = data["spk"]
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, {"descr": "|u1", "fortran_order": bool(rng.random() < 0.2),
                                                   "shape": tuple(shape)})
        with zipfile.ZipFile(path, "a") as zf:
            # a second member of the same name: readers take the last one written
            zf.writestr("spk.npy", buf.getvalue() + spk.tobytes())
        return path, f"shape {shape}"
    if kind == "delete" and len(files) > 1:
        target.unlink()
        return path, f"delete {target.relative_to(folder)}"
    data = bytearray(target.read_bytes())
    if kind == "truncate" and data:
        cut = int(rng.integers(0, len(data)))
        target.write_bytes(bytes(data[:cut]))
        return path, f"truncate {target.relative_to(folder)} to {cut}"
    if kind == "append":
        target.write_bytes(bytes(data) + rng.bytes(int(rng.integers(1, 64))))
        return path, f"append to {target.relative_to(folder)}"
    n = int(rng.integers(1, 9))
    for _ in range(n):
        if data:
            i = int(rng.integers(len(data)))
            data[i] ^= 1 << int(rng.integers(8))
    target.write_bytes(bytes(data))
    return path, f"flip {n} bits in {target.relative_to(folder)}"


def _unmark(rng, fmt: str, path: Path) -> str:
    """Delete integrity fields (and maybe edit the version down) as a user with a text editor would."""
    if fmt == "dat":
        side = path.with_name(path.name + ".json")
        header = json.loads(side.read_text())
        dropped = [k for k in ("blake2b", "sidecar_blake2b", "block_crc32", "block_bytes", "data_bytes")
                   if rng.random() < 0.6] or ["blake2b", "sidecar_blake2b"]
        for k in dropped:
            header.pop(k, None)
        if rng.random() < 0.5:
            header["version"] = 1
            dropped.append("version=1")
        side.write_text(json.dumps(header))
        return f"unmark sidecar {dropped}"
    if fmt == "zarr":
        meta_file = path / "zarr.json"
        meta = json.loads(meta_file.read_text())
        header = meta["attributes"]["viform"]
        header["version"] = 1
        dropped = [k for k in ("chunks", "header_blake2b", "chunk_ticks", "n_ticks") if rng.random() < 0.5]
        for k in dropped:
            header.pop(k, None)
        meta_file.write_text(json.dumps(meta))
        return f"unmark zarr version=1, drop {dropped}"
    with np.load(path) as data:
        members = {k: data[k] for k in data.files}
    header = json.loads(str(members["viform_header"]))
    dropped = [k for k in ("block_crc32", "block_bytes", "header_blake2b", "member_bytes", "format")
               if rng.random() < 0.5] or ["block_crc32"]
    for k in dropped:
        header.pop(k, None)
    members["viform_header"] = np.array(json.dumps(header))
    with open(path, "wb") as f:
        np.savez(f, **members)
    return f"unmark npz header {dropped}"


def commands(fmt: str, path: Path, out: Path, case: int = 0) -> list[list[str]]:
    """The reading commands; ``reconstruct`` reads part of the stream (an early and a later
    instant of the 4 ms stream), its method taken in turn from :data:`METHODS`."""
    p = str(path)
    if fmt == "vfc":
        return [["info", p], ["verify", p], ["decode", p, str(out / "d.npz")], ["decode", p, str(out / "d.zarr")]]
    early, late = METHODS[case % len(METHODS)], METHODS[(case + 2) % len(METHODS)]
    return [["info", p], ["verify", p],
            ["reconstruct", p, "--method", early, "--at", "0.0004", "--out", str(out / "r")],
            ["reconstruct", p, "--method", late, "--at", "0.0025", "--out", str(out / "a")],
            ["encode", p, str(out / "e.vfc")]]


def result_digest(args: list[str], out: Path, stdout: str) -> str | None:
    """What a command produced, to compare with the intact file's: the images of ``reconstruct``
    (every array of its light.npz), the bits of ``encode``'s output; None for the others."""
    h = hashlib.blake2b(digest_size=16)
    if args[0] == "reconstruct":
        light = Path(args[args.index("--out") + 1]) / "light.npz"
        if not light.is_file():
            return "no output"
        with np.load(light) as data:
            for key in sorted(data.files):
                h.update(key.encode() + np.ascontiguousarray(data[key]).tobytes())
        return h.hexdigest()
    if args[0] == "encode":
        from viform.coding.aer_file import CodedFile

        coded = Path(args[2])
        if not coded.is_file():
            return "no output"
        for _, block in CodedFile(coded).iter_blocks(64):
            h.update(np.packbits(block).tobytes())
        return h.hexdigest()
    return None


# ---------------------------------------------------------------- running
def run_command(args: list[str], timeout_s: float = COMMAND_TIMEOUT_S) -> dict:
    from viform.cli import main

    err, out = io.StringIO(), io.StringIO()

    def on_alarm(signum, frame):
        raise Hang()

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    started = time.perf_counter()
    try:
        with redirect_stderr(err), redirect_stdout(out):
            rc = main(args)
    except Hang:
        rc = "hang"
    except BaseException as exc:  # escaped main(): a crash of the entry point
        rc = f"escaped {type(exc).__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return {"rc": rc, "err": err.getvalue(), "out": out.getvalue()[-300:], "s": time.perf_counter() - started}


def leftovers(*folders: Path) -> list[str]:
    found = []
    for folder in folders:
        if folder.exists():
            found += [str(p) for p in folder.rglob("*") if ".viform-tmp" in p.name or ".viform-old" in p.name]
    return found


def classify(cmd: str, result: dict, fp_original, fp_damaged, what: str = "", output=None,
             output_original=None) -> str:
    """ok | refused | internal | crash | hang | silent | forged-accepted | multiline | ok-unverified.

    ``forged-accepted``: a header field set to another value that is valid for it, with the
    header's checksum recomputed — a deliberate, consistent forgery that no checksum can tell
    from a real file (reported, reviewed by hand; not a failure). ``output``: what the command
    produced (:func:`result_digest`); exit 0 with an output different from the intact file's is
    ``silent`` whatever the rest of the file holds.
    """
    rc, err = result["rc"], result["err"]
    if rc == "hang":
        return "hang"
    if not isinstance(rc, int):
        return "crash"
    lines = [line for line in err.splitlines() if line.strip() and "%|" not in line and "tick/s" not in line
             and not line.startswith("compiling ")]  # the first-run compile notice is not an error line
    if rc == 2:
        return "refused" if len(lines) == 1 and "Traceback" not in err and "internal error" not in err \
            else "multiline"
    if rc == 1 or "internal error" in err:
        return "internal"
    if rc != 0:
        return "crash"
    # exit 0: right only if what it produced (or, for info/verify, what was read) equals the undamaged file's
    if what.startswith("forge") and fp_damaged is not None and not fp_damaged.startswith("error") \
            and fp_damaged != fp_original:
        return "forged-accepted"
    if output_original is not None:
        return "ok" if output == output_original else "silent"
    if fp_damaged == fp_original:
        return "ok"
    if fp_damaged is None and cmd == "info" and '"verified": true' not in result["out"] \
            and "verified: yes" not in result["out"]:
        return "ok-unverified"  # info said it did not verify
    return "silent"


def run_cases(seed: int, n_cases: int, work: Path, formats=FORMATS) -> dict:
    """Run ``n_cases`` mutation cases; returns counts and examples of each failure kind."""
    from viform.stream import checksums

    checksums.MIN_BLOCK_BYTES = FUZZ_BLOCK_BYTES  # many blocks in a tiny file (see the module docstring)
    rng = np.random.default_rng(seed)
    originals = make_originals(work)
    fp_original = {fmt: fingerprint(p) for fmt, p in originals.items()}
    intact_outputs: dict[tuple, str | None] = {}

    def intact_output(fmt, case, index):
        """The output of the same command on the undamaged file (run once per command)."""
        key = (fmt, index, case % len(METHODS))
        if key not in intact_outputs:
            out = work / "intact"
            out.mkdir(exist_ok=True)
            args = commands(fmt, originals[fmt], out, case)[index]
            result = run_command(args)
            assert result["rc"] == 0, (args, result)
            intact_outputs[key] = result_digest(args, out, result["out"])
            shutil.rmtree(out)
        return intact_outputs[key]

    counts: dict[str, int] = {}
    examples: dict[str, list] = {}
    runs = 0
    for case in range(n_cases):
        fmt = formats[case % len(formats)]
        folder = work / f"case{case}"
        folder.mkdir()
        path, what = mutate(rng, fmt, originals[fmt], folder)
        fp = fingerprint(path)
        for index, args in enumerate(commands(fmt, path, folder / "out", case)):
            (folder / "out").mkdir(exist_ok=True)
            result = run_command(args)
            runs += 1
            output_original = intact_output(fmt, case, index) if result["rc"] == 0 else None
            output = result_digest(args, folder / "out", result["out"]) if result["rc"] == 0 else None
            kind = classify(args[0], result, fp_original[fmt], fp, what, output, output_original)
            left = leftovers(folder)
            if left:
                kind_left = "temp-left"
                counts[kind_left] = counts.get(kind_left, 0) + 1
                examples.setdefault(kind_left, []).append([what, args[0], left[:3]])
            if kind in ("refused",) and any(p.name in ("light.npz", "e.vfc", "d.npz", "d.zarr") or p.suffix == ".png"
                                           for p in (folder / "out").rglob("*")):
                kind = "partial-output"
            counts[kind] = counts.get(kind, 0) + 1
            if kind not in ("ok", "refused", "ok-unverified") and len(examples.get(kind, [])) < 12:
                examples.setdefault(kind, []).append([fmt, what, " ".join(args[:1]), result["rc"],
                                                      result["err"].strip()[-300:]])
            shutil.rmtree(folder / "out", ignore_errors=True)
        shutil.rmtree(folder, ignore_errors=True)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"cases": n_cases, "runs": runs, "counts": counts, "examples": examples, "peak_rss_mb": peak_mb}


def worker(seed: int, n_cases: int, result_file: str) -> None:
    with tempfile.TemporaryDirectory(prefix="viform-fuzz-") as work:
        result = run_cases(seed, n_cases, Path(work))
    Path(result_file).write_text(json.dumps(result, indent=1, default=str))


def run_worker(seed: int, n_cases: int, timeout_s: float) -> dict:
    """Run the cases in a fresh process (so a crash, a hang or memory growth is seen from outside)."""
    with tempfile.TemporaryDirectory(prefix="viform-fuzz-result-") as folder:
        result_file = Path(folder) / "result.json"
        proc = subprocess.run([sys.executable, __file__, "--worker", "--seed", str(seed), "--cases", str(n_cases),
                               "--result", str(result_file)], capture_output=True, text=True, timeout=timeout_s,
                              env={**os.environ, "VIFORM_DEBUG": ""})
        assert proc.returncode == 0, proc.stderr[-2000:]
        return json.loads(result_file.read_text())


# ---------------------------------------------------------------- the suite
def test_damaged_files_fail_cleanly():
    """50 seeded cases × 4–5 commands: exit 0 with the undamaged result, or exit 2 with one line."""
    result = run_worker(seed=11, n_cases=50, timeout_s=180)
    counts = result["counts"]
    bad = {k: v for k, v in counts.items()
           if k not in ("ok", "refused", "ok-unverified", "forged-accepted")}
    assert bad == {}, json.dumps(result["examples"], indent=1)[:4000]
    assert counts.get("refused", 0) > result["runs"] // 3  # the mutations do damage
    assert result["peak_rss_mb"] < 1024


def test_degenerate_streams_get_one_line_from_every_command(tmp_path):
    """0 ticks: exit 2, one line naming the file; 1 tick: every command works (issue 26.2)."""
    from viform.stream.container import SpikeStream
    from viform.stream.io import save_spikes

    empty = tmp_path / "empty.npz"
    np.savez(empty, spk=np.zeros((0, 8, 16), np.uint8))
    one = save_spikes(tmp_path / "one.dat", SpikeStream(np.ones((1, 8, 16), bool), 40_000.0, 60.0))
    for path, expect in ((empty, 2), (one, 0)):
        runs = [["info", str(path)], ["verify", str(path)], ["encode", str(path), str(tmp_path / "o.vfc")]]
        runs += [["reconstruct", str(path), "--method", m, "--at", "0", "--out", str(tmp_path / f"{m}.png")]
                 for m in METHODS]
        for args in runs:
            result = run_command(args)
            assert result["rc"] == expect, (args, result)
            if expect == 2:
                assert result["err"].count("\n") == 1 and "empty.npz" in result["err"] \
                    and "empty stream" in result["err"], result["err"]


def main_cli() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=400)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--worker", action="store_true")
    parser.add_argument("--result")
    args = parser.parse_args()
    if args.worker:
        worker(args.seed, args.cases, args.result)
        return
    started = time.perf_counter()
    result = run_worker(args.seed, args.cases, timeout_s=24 * 3600)
    result["elapsed_s"] = round(time.perf_counter() - started, 1)
    print(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main_cli()
