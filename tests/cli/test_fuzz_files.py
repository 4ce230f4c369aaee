"""Fuzzing the readers through the CLI: damaged, edited and forged .dat/.npz/.zarr/.vfc files.

Each case copies a small good file, changes it one way and runs ``info``, ``verify``,
``reconstruct`` (partial reads: an early and a later instant, each method in turn), ``encode``
or ``decode`` on it, in a worker process. The changes come in five categories:

``mutation``
    bit flips (anywhere, or late in the data where only per-block checks see them in a partial
    read), truncation, appended bytes, a deleted chunk or sidecar, a forged array shape;
``switch-off``
    integrity edited away by hand, then one spike flipped: checksum fields deleted (some, or all
    of them with or without the provenance), the version edited down, the ``.npz`` header member
    removed, the zip rewritten so its own CRC-32 matches;
``forged``
    one header field set to another value with the header's checksum recomputed (random values,
    and the edits an attacker would try: ``null`` numbers, unknown fields, a narrower width, the
    row order, ``k`` and Q of a ``.vfc``);
``tail``
    bytes after the end record, the file joined to itself, bytes in front;
``bomb``
    another tool's ``.npz`` whose spike member is mostly zeros (:data:`BOMB_MB` MB that deflate
    to a few kB), read at two early instants: the work of a partial read (bytes inflated) must be
    bounded by what the same read of viform's own ``.npz`` of the same spikes costs.

Outcomes, per run: ``identical`` (exit 0, the same result as the original: the images of
``reconstruct`` value for value, the bits of ``encode``/``decode``, what a reader reads for
``info``/``verify``), ``refused`` (exit 2, one line, no traceback), ``unverified`` (the data was
read, and the command said it was unverified: a warning, ``verified: no``, or ``verify``'s exit
status 3), ``forged-accepted`` (a forged field taken at its word: a consistent edit no unkeyed
checksum can tell from a written file; reviewed by hand), and the failures: ``silent`` (exit 0
with a different result, unsaid), ``accepted`` (a ``tail`` change read with exit 0, whatever the
result), ``internal`` (exit 1), ``crash``, ``multiline``, ``hang``
(past :data:`COMMAND_CPU_S` of CPU or :data:`COMMAND_WALL_S` of wall time), ``unbounded``
(the bomb inflated more than a bounded read), ``partial-output`` (refused, but left outputs),
and ``leftovers`` (temporary files left; counted beside the outcome).

No limit depends on the machine's speed: a command is a hang only after minutes of CPU time
(a busy loop) or of wall time (a deadlock) where it needs a fraction of a second.

viform's block checksums are made small here (:data:`FUZZ_BLOCK_BYTES`) so that the tiny
files have many blocks and a partial read touches only some of them, as a real file's does;
and the whole-member check of another tool's ``.npz`` stops at :data:`FUZZ_WHOLE_CHECK_BYTES`.

Run a bigger campaign (outside the suite) with::

    python tests/cli/test_fuzz_files.py --cases 2000 --seed 1 [--bomb-mb 2000]
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
import zlib
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from viform.stream.container import SpikeSource

FORMATS = ("dat", "npz", "zarr", "vfc", "zoo")
CATEGORIES = ("mutation", "switch-off", "forged", "tail", "bomb")
#: Formats each category changes.
CATEGORY_FORMATS = {"mutation": FORMATS, "switch-off": ("dat", "npz", "zarr"), "forged": FORMATS,
                    "tail": ("npz", "zoo", "vfc", "dat"), "bomb": ("bomb",)}
#: The order cases are drawn in (cycled): 4 mutation, 2 switch-off, 2 forged, 1 tail, 1 bomb in 10.
SCHEDULE = ("mutation", "switch-off", "forged", "mutation", "tail", "mutation", "forged", "switch-off", "mutation",
            "bomb")
METHODS = ("accumulation", "interval", "multi-interval", "motion")
#: Block size of viform's per-block checksums in the campaign (1 MiB in real files).
FUZZ_BLOCK_BYTES = 512
#: Largest foreign spike member checked whole before a read, in the campaign (256 MiB in real use).
FUZZ_WHOLE_CHECK_BYTES = 4 << 20
#: Size of the bomb's spike member, MB (``--bomb-mb`` for long runs; the campaign of issue 39 used 2000).
BOMB_MB = 48
#: Bytes a bounded partial read of the bomb may inflate beyond the same read of viform's own file.
BOMB_SLACK_BYTES = 8 << 20
FORGED_VALUES = [-1, 0, 0.5, 1e308, -1e308, 2**63, 1e12, 65537, "nan", "x", None, [], {}, True,
                 float("nan"), float("inf")]
#: A command is a hang after this much CPU time (a busy loop; these commands need < 1 s) ...
COMMAND_CPU_S = 300.0
#: ... or this much wall-clock time (a deadlock uses no CPU; generous for a loaded machine).
COMMAND_WALL_S = 1800.0
#: Outcomes that are not failures.
GOOD = ("identical", "refused", "unverified", "forged-accepted")


class Hang(BaseException):
    """A command ran past its limit."""


# ---------------------------------------------------------------- originals
def _stream():
    from viform.sensors.spike import SpikeSensor
    from viform.stream.container import SpikeStream

    rng = np.random.default_rng(0)
    meta = {"sensor": SpikeSensor(threshold_electrons=60.0).describe(), "scene": {"name": "fuzz"}, "seed": 1}
    return SpikeStream(rng.random((160, 8, 16)) < 0.2, 40_000.0, 60.0, 0.0, meta)


def make_originals(folder: Path, bomb_mb: float = BOMB_MB) -> dict:
    from viform.coding.aer_file import encode_source
    from viform.stream.io import save_spikes

    stream = _stream()
    paths = {}
    for fmt in ("dat", "npz", "zarr"):
        paths[fmt] = save_spikes(folder / f"orig.{fmt}", stream, block_ticks=32)
    paths["vfc"] = folder / "orig.vfc"
    encode_source(stream, paths["vfc"], "strict", segment_ticks=64)
    paths["zoo"] = folder / "zoo.npz"  # another tool's layout: Spike-Zoo's key and scalars, compressed
    np.savez_compressed(paths["zoo"], spk=stream.spikes.astype(np.uint8), clock_hz=np.float64(40_000.0))
    paths["bomb"], paths["bomb-reference"] = make_bomb(folder, bomb_mb)
    return paths


class _BombSource(SpikeSource):
    """The bomb's spikes, block by block: random in the first :data:`BOMB_BUSY_TICKS`, zeros after."""

    height, width = 64, 128

    def __init__(self, n_ticks: int):
        self.n_ticks, self.clock_hz, self.threshold_electrons, self.start_time_s = n_ticks, 40_000.0, None, 0.0
        self.metadata = {}

    def read_ticks(self, start, stop):
        out = np.zeros((stop - start, self.height, self.width), bool)
        busy = min(stop, BOMB_BUSY_TICKS)
        if busy > start:
            spikes = np.random.default_rng(2).random((BOMB_BUSY_TICKS, self.height, self.width)) < 0.2
            out[: busy - start] = spikes[start:busy]
        return out


BOMB_BUSY_TICKS = 400


def make_bomb(folder: Path, bomb_mb: float) -> tuple[Path, Path]:
    """Another tool's compressed ``.npz`` of ``bomb_mb`` MB of spikes (few kB on disk), written in
    blocks, and viform's own ``.npz`` of the same spikes (the cost a bounded read is held to)."""
    from viform.stream.npz import write_npz

    source = _BombSource(max(BOMB_BUSY_TICKS * 2, int(bomb_mb * 1e6) // (64 * 128)))
    bomb = folder / "bomb.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|u1", "fortran_order": False,
                                                  "shape": (source.n_ticks, 64, 128)})
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        with zf.open("spk.npy", "w", force_zip64=True) as fp:
            fp.write(header.getvalue())
            for first in range(0, source.n_ticks, 1024):
                fp.write(source.read_ticks(first, min(first + 1024, source.n_ticks)).astype(np.uint8).tobytes())
        with zf.open("clock_hz.npy", "w") as fp:
            np.lib.format.write_array(fp, np.float64(40_000.0))
    reference = write_npz(folder / "bomb-reference.npz", source)
    return bomb, reference


def fingerprint(path: Path) -> str | None:
    """What a reader gets from the file (bits and the fields that change results), or None if refused."""
    import warnings

    from viform._validate import ViformError
    from viform.stream.io import open_spikes

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
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


# ---------------------------------------------------------------- changes
def _files_of(path: Path) -> list[Path]:
    if path.is_dir():
        return sorted(p for p in path.rglob("*") if p.is_file())
    side = path.with_name(path.name + ".json")
    return [path] + ([side] if side.exists() else [])


def _copy(original: Path, folder: Path) -> Path:
    from viform.stream import sidecar

    path = folder / original.name
    if original.is_dir():
        shutil.copytree(original, path)
    else:
        shutil.copy(original, path)
        side = sidecar.sidecar_path(original)
        if side.exists():
            shutil.copy(side, sidecar.sidecar_path(path))
    return path


def change(rng, category: str, fmt: str, original: Path, folder: Path) -> tuple[Path, str]:
    """Copy ``original`` into ``folder`` and change the copy one way of ``category``."""
    path = _copy(original, folder)
    if category == "bomb":
        return path, "bomb"
    return path, {"mutation": mutate, "switch-off": switch_off, "forged": forge, "tail": tail}[category](
        rng, fmt, path, folder)


def mutate(rng, fmt: str, path: Path, folder: Path) -> str:
    """Damage: bit flips, truncation, appended bytes, a deleted file, a forged array shape."""
    files = _files_of(path)
    kind = rng.choice(["flip", "flip", "truncate", "append", "delete", "shape", "late"])
    target = files[rng.integers(len(files))]
    if kind == "late":  # damage past the instants read early: only per-block checks catch it in a partial read
        target = max(_files_of(path), key=lambda p: p.stat().st_size)
        data = bytearray(target.read_bytes())
        i = int(rng.integers(len(data) // 2, len(data)))
        data[i] ^= 1 << int(rng.integers(8))
        target.write_bytes(bytes(data))
        return f"flip a bit of byte {i} of {target.relative_to(folder)}"
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
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                zf.writestr("spk.npy", buf.getvalue() + spk.tobytes())
        return f"shape {shape}"
    if kind == "delete" and len(files) > 1:
        target.unlink()
        return f"delete {target.relative_to(folder)}"
    data = bytearray(target.read_bytes())
    if kind == "truncate" and data:
        cut = int(rng.integers(0, len(data)))
        target.write_bytes(bytes(data[:cut]))
        return f"truncate {target.relative_to(folder)} to {cut}"
    if kind == "append":
        target.write_bytes(bytes(data) + rng.bytes(int(rng.integers(1, 64))))
        return f"append to {target.relative_to(folder)}"
    n = int(rng.integers(1, 9))
    for _ in range(n):
        if data:
            i = int(rng.integers(len(data)))
            data[i] ^= 1 << int(rng.integers(8))
    target.write_bytes(bytes(data))
    return f"flip {n} bits in {target.relative_to(folder)}"


#: Spikes the switch-off edits flip (tick, row, column): near both instants ``reconstruct`` reads.
FLIPPED_SPIKES = ((15, 3, 5), (16, 3, 5), (17, 3, 5), (99, 4, 9), (100, 4, 9), (101, 4, 9))
#: Integrity fields of each format, and the provenance viform writes beside them.
SIDECAR_MARKS = ("format", "version", "sidecar_blake2b", "blake2b", "data_bytes", "block_bytes", "block_crc32",
                 "viform_version")
NPZ_MARKS = ("format", "version", "member_bytes", "block_bytes", "block_crc32", "header_blake2b")
PROVENANCE = ("viform_version", "command_line", "utc_date")


def _flip_spikes(fmt: str, path: Path) -> None:
    """Flip :data:`FLIPPED_SPIKES` in the data, leaving the container's own checks consistent."""
    if fmt == "dat":
        from viform.stream.dat import pack_frames

        side = json.loads(path.with_name(path.name + ".json").read_text()) \
            if path.with_name(path.name + ".json").exists() else {}
        flip = side.get("rows", "bottom-up") == "bottom-up"
        raw = bytearray(path.read_bytes())
        frame = 8 * 16 // 8
        for t, r, c in FLIPPED_SPIKES:
            bits = np.unpackbits(np.frombuffer(bytes(raw[t * frame:(t + 1) * frame]), np.uint8),
                                 bitorder="little").reshape(8, 16).astype(bool)
            bits = bits[::-1] if flip else bits
            bits[r, c] ^= True
            raw[t * frame:(t + 1) * frame] = pack_frames(bits[None], flip=flip)
        path.write_bytes(bytes(raw))
    elif fmt == "zarr":
        import zarr

        array = zarr.open_array(store=str(path), mode="r+")
        for t, r, c in FLIPPED_SPIKES:
            row = np.asarray(array[t, r])
            row[c // 8] ^= 1 << (c % 8)
            array[t, r] = row
    else:
        with np.load(path) as data:
            members = {k: data[k] for k in data.files}
        spk = members["spk"].copy()
        for t, r, c in FLIPPED_SPIKES:
            spk[t, r, c] ^= 1
        members["spk"] = spk
        with open(path, "wb") as f:
            np.savez_compressed(f, **members)


def switch_off(rng, fmt: str, path: Path, folder: Path) -> str:
    """Integrity edited away as a user with a text editor would, then spikes flipped."""
    kind = rng.choice(["some", "marks", "all", "no-header"] if fmt == "npz" else ["some", "marks", "all"])
    if fmt == "dat":
        side = path.with_name(path.name + ".json")
        header = json.loads(side.read_text())
        if kind == "some":
            dropped = [k for k in ("blake2b", "sidecar_blake2b", "block_crc32", "block_bytes", "data_bytes")
                       if rng.random() < 0.6] or ["blake2b", "sidecar_blake2b"]
            if rng.random() < 0.5:
                header["version"] = 1
                dropped.append("version=1")
        else:  # every field viform marks its sidecars with (and, for "all", the provenance too)
            dropped = list(SIDECAR_MARKS) + (list(PROVENANCE) if kind == "all" else [])
        for k in dropped:
            header.pop(k, None)
        side.write_text(json.dumps(header))
        what = f"sidecar {kind}: drop {dropped}"
    elif fmt == "zarr":
        meta_file = path / "zarr.json"
        meta = json.loads(meta_file.read_text())
        header = meta["attributes"]["viform"]
        header["version"] = 1
        dropped = [k for k in ("chunks", "header_blake2b", "chunk_ticks", "n_ticks") if rng.random() < 0.5] \
            if kind == "some" else ["chunks", "header_blake2b", "chunk_ticks", "n_ticks"] + \
            (list(PROVENANCE) if kind == "all" else [])
        for k in dropped:
            header.pop(k, None)
        meta_file.write_text(json.dumps(meta))
        what = f"zarr {kind}: version=1, drop {dropped}"
    else:
        with np.load(path) as data:
            members = {k: data[k] for k in data.files}
        header = json.loads(str(members["viform_header"]))
        if kind == "some":
            dropped = [k for k in NPZ_MARKS[2:] + ("format",) if rng.random() < 0.5] or ["block_crc32"]
        else:
            dropped = list(NPZ_MARKS) + (list(PROVENANCE) if kind == "all" else [])
        for k in dropped:
            header.pop(k, None)
        members["viform_header"] = np.array(json.dumps(header))
        if kind == "no-header":
            del members["viform_header"]
            dropped = ["viform_header member"]
        with open(path, "wb") as f:
            np.savez(f, **members)
        what = f"npz {kind}: drop {dropped}"
    _flip_spikes(fmt, path)
    return f"{what}; flip {len(FLIPPED_SPIKES)} spikes"


def _forge_json(rng, header: dict) -> str:
    key = str(rng.choice(sorted(header)))
    value = FORGED_VALUES[rng.integers(len(FORGED_VALUES))]
    if rng.random() < 0.2:
        header.pop(key)
        return f"drop {key}"
    header[key] = value
    return f"{key}={value!r}"


#: The edits an attacker would try first, by format: (field, value); ``None`` as field adds an unknown one.
TARGETED = {
    "dat": [("rows", "upright"), ("clock_hz", None), ("n_ticks", None), ("stored_width", 24), ("width", 8),
            ("threshold_electrons", None)],
    "npz": [("rows", "bottom-up"), ("axes", "htw"), ("clock_hz", None), ("x_unknown", 1), ("width", 8),
            ("threshold_electrons", None)],
    "zarr": [("width", 13), ("width", 9), ("rows", "bottom-up"), ("clock_hz", None), ("x_unknown", 1),
             ("threshold_electrons", None)],
    "vfc": [("threshold_electrons", None), ("k", 0), ("x_unknown", 1), ("height", 16), ("width", 8),
            ("mode", "statistical"), ("clock_hz", 1000.0), ("slack_ticks", None)],
}


def _set(header: dict, field: str, value) -> str:
    header[field] = value
    return f"{field}={value!r}"


def forge(rng, fmt: str, path: Path, folder: Path) -> str:
    """One header field changed, the header's checksum recomputed (random or targeted edits)."""
    from viform.stream import sidecar, zarr_store

    targeted = fmt in TARGETED and rng.random() < 0.5
    pick = TARGETED[fmt][rng.integers(len(TARGETED[fmt]))] if targeted else None

    def edit(header):
        return _set(header, *pick) if pick is not None else _forge_json(rng, header)

    if fmt == "dat":
        side = sidecar.sidecar_path(path)
        header = json.loads(side.read_text())
        what = edit(header)
        header[sidecar.DIGEST_KEY] = sidecar._digest(header)
        side.write_text(json.dumps(header))
    elif fmt == "zarr":
        meta_file = path / "zarr.json"
        meta = json.loads(meta_file.read_text())
        what = edit(meta["attributes"]["viform"])
        meta["attributes"]["viform"]["header_blake2b"] = zarr_store._header_digest(meta["attributes"]["viform"])
        meta_file.write_text(json.dumps(meta))
    elif fmt == "vfc":
        what = _forge_vfc(rng, path, pick)
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
            what = edit(header)
            header["header_blake2b"] = header_digest(header)
            members["viform_header"] = np.array(json.dumps(header))
        with open(path, "wb") as f:
            np.savez(f, **members)
    return f"forge {what}"


def _forge_vfc(rng, path: Path, pick) -> str:
    """A ``.vfc`` header field changed and the header's CRC-32 recomputed (its length may change)."""
    import struct

    raw = path.read_bytes()
    version, hlen, _ = struct.unpack_from("<HII", raw, 8)
    header = json.loads(raw[18:18 + hlen])
    what = _set(header, *pick) if pick is not None else _forge_json(rng, header)
    head = json.dumps(header).encode()
    path.write_bytes(raw[:8] + struct.pack("<HII", version, len(head), zlib.crc32(head)) + head + raw[18 + hlen:])
    return what


def tail(rng, fmt: str, path: Path, folder: Path) -> str:
    """Bytes around the file's own structure: after its end, the file joined to itself, in front."""
    target = path
    data = target.read_bytes()
    kind = rng.choice(["junk after", "itself after", "zeros after"] + (["junk before"] if fmt != "dat" else []))
    if kind == "junk after":
        target.write_bytes(data + rng.bytes(int(rng.integers(1, 64))))
    elif kind == "itself after":
        target.write_bytes(data + data)
    elif kind == "zeros after":
        target.write_bytes(data + bytes(int(rng.integers(1, 4096))))
    else:
        target.write_bytes(rng.bytes(int(rng.integers(1, 64))) + data)
    return kind


# ---------------------------------------------------------------- commands
def commands(fmt: str, path: Path, out: Path, case: int = 0) -> list[list[str]]:
    """The reading commands; ``reconstruct`` reads part of the stream (an early and a later
    instant of the 4 ms stream), its method taken in turn from :data:`METHODS`."""
    p = str(path)
    early, late = METHODS[case % len(METHODS)], METHODS[(case + 2) % len(METHODS)]
    if fmt == "bomb":
        return [["reconstruct", p, "--method", early, "--at", "0.0004", "--out", str(out / "r")],
                ["reconstruct", p, "--method", late, "--at", "0.0025", "--out", str(out / "a")]]
    if fmt == "vfc":
        return [["info", p], ["verify", p], ["decode", p, str(out / "d.npz")], ["decode", p, str(out / "d.zarr")]]
    return [["info", p], ["verify", p],
            ["reconstruct", p, "--method", early, "--at", "0.0004", "--out", str(out / "r")],
            ["reconstruct", p, "--method", late, "--at", "0.0025", "--out", str(out / "a")],
            ["encode", p, str(out / "e.vfc")]]


def result_digest(args: list[str], out: Path) -> str | None:
    """What a command produced, to compare with the original's: the images of ``reconstruct``
    (every array of its light.npz), the bits of ``encode``'s and ``decode``'s output; None for
    ``info``/``verify`` (what a reader reads from the file is compared instead)."""
    import warnings

    h = hashlib.blake2b(digest_size=16)
    if args[0] == "reconstruct":
        light = Path(args[args.index("--out") + 1]) / "light.npz"
        if not light.is_file():
            return "no output"
        with np.load(light) as data:
            for key in sorted(data.files):
                h.update(key.encode() + np.ascontiguousarray(data[key]).tobytes())
        return h.hexdigest()
    if args[0] in ("encode", "decode"):
        from viform.stream.io import open_spikes

        written = Path(args[2])
        if not written.exists():
            return "no output"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if args[0] == "encode":
                from viform.coding.aer_file import CodedFile

                source = CodedFile(written)
            else:
                source = open_spikes(written)
            for _, block in source.iter_blocks(64):
                h.update(np.packbits(block).tobytes())
        return h.hexdigest()
    return None


# ---------------------------------------------------------------- running
class _Inflated:
    """Bytes inflated from zip members in this process (the work of a read of a ``.npz``)."""

    total = 0

    @classmethod
    def install(cls) -> None:
        if getattr(zipfile.ZipExtFile, "_fuzz_counted", False):
            return
        read, read1 = zipfile.ZipExtFile.read, zipfile.ZipExtFile.read1

        def counted_read(self, n=-1):
            data = read(self, n)
            cls.total += len(data)
            return data

        def counted_read1(self, n):
            data = read1(self, n)
            cls.total += len(data)
            return data

        zipfile.ZipExtFile.read, zipfile.ZipExtFile.read1 = counted_read, counted_read1
        zipfile.ZipExtFile._fuzz_counted = True


def run_command(args: list[str], cpu_s: float = COMMAND_CPU_S, wall_s: float = COMMAND_WALL_S) -> dict:
    """Run ``viform ARGS`` in this process; a hang is past ``cpu_s`` of CPU time or ``wall_s`` of wall time."""
    from viform.cli import main

    err, out = io.StringIO(), io.StringIO()

    def on_limit(signum, frame):
        raise Hang()

    old = {s: signal.signal(s, on_limit) for s in (signal.SIGALRM, signal.SIGPROF)}
    signal.setitimer(signal.ITIMER_REAL, wall_s)
    signal.setitimer(signal.ITIMER_PROF, cpu_s)
    inflated = _Inflated.total
    cpu_started = time.process_time()
    try:
        with redirect_stderr(err), redirect_stdout(out):
            rc = main(args)
    except Hang:
        rc = "hang"
    except BaseException as exc:  # escaped main(): a crash of the entry point
        rc = f"escaped {type(exc).__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.setitimer(signal.ITIMER_PROF, 0)
        for s, handler in old.items():
            signal.signal(s, handler)
    return {"rc": rc, "err": err.getvalue(), "out": out.getvalue()[-20000:],
            "cpu_s": time.process_time() - cpu_started, "inflated": _Inflated.total - inflated}


def leftovers(*folders: Path) -> list[str]:
    found = []
    for folder in folders:
        if folder.exists():
            found += [str(p) for p in folder.rglob("*") if ".viform-tmp" in p.name or ".viform-old" in p.name]
    return found


def error_lines(err: str) -> list[str]:
    """stderr lines that are not progress, the first-run compile notice or a warning."""
    return [line for line in err.splitlines() if line.strip() and "%|" not in line and "tick/s" not in line
            and not line.startswith(("compiling ", "viform: warning:"))]


def said_unverified(cmd: str, result: dict) -> bool:
    """The command said that what it read is not verified (``verify`` only by its exit status)."""
    if cmd == "verify":
        return result["rc"] == 3
    text = result["err"] + result["out"]
    return "read unverified" in text or "verified: no" in text or '"verified": false' in text


def classify(category: str, cmd: str, result: dict, fp_original, fp_changed, output=None,
             output_original=None) -> str:
    """The outcome of one run (see the module docstring)."""
    rc, err = result["rc"], result["err"]
    if rc == "hang":
        return "hang"
    if not isinstance(rc, int):
        return "crash"
    if rc == 2:
        lines = error_lines(err)
        return "refused" if len(lines) == 1 and "Traceback" not in err and "internal error" not in err \
            else "multiline"
    if rc == 1 or "internal error" in err:
        return "internal"
    if rc == 3 and cmd == "verify":
        return "unverified" if fp_changed is not None else "silent"  # readable: a reader gets its data
    if rc != 0:
        return "crash"
    if category == "tail":
        return "accepted"  # bytes around the file's own structure must be refused, whatever is read
    same = output == output_original if output_original is not None else fp_changed == fp_original
    if same:
        return "identical"
    if category == "forged" and fp_changed is not None and not fp_changed.startswith("error") \
            and fp_changed != fp_original:
        return "forged-accepted"  # a consistent edit, taken at its word (reviewed by hand)
    if said_unverified(cmd, result) and cmd != "verify":
        return "unverified"
    return "silent"


def run_cases(seed: int, n_cases: int, work: Path, bomb_mb: float = BOMB_MB, categories=CATEGORIES) -> dict:
    """Run ``n_cases`` cases (categories drawn in :data:`SCHEDULE` order); returns counts by category."""
    from viform.stream import checksums, npz

    checksums.MIN_BLOCK_BYTES = FUZZ_BLOCK_BYTES  # many blocks in a tiny file (see the module docstring)
    npz.WHOLE_CHECK_BYTES = FUZZ_WHOLE_CHECK_BYTES
    _Inflated.install()
    rng = np.random.default_rng(seed)
    originals = make_originals(work, bomb_mb)
    fp_original = {fmt: fingerprint(p) for fmt, p in originals.items() if fmt != "bomb"}
    fp_original["bomb"] = fp_original.pop("bomb-reference")
    intact: dict[tuple, tuple] = {}

    def intact_output(fmt, case, index):
        """The output of the same command on the original (run once per command); for the bomb, on
        viform's own .npz of the same spikes."""
        key = (fmt, index, case % len(METHODS))
        if key not in intact:
            out = work / "intact"
            out.mkdir(exist_ok=True)
            original = originals["bomb-reference" if fmt == "bomb" else fmt]
            args = commands(fmt, original, out, case)[index]
            result = run_command(args)
            assert result["rc"] == 0, (args, result)
            intact[key] = (result_digest(args, out), result["inflated"])
            shutil.rmtree(out)
        return intact[key]

    schedule = [c for c in SCHEDULE if c in categories]
    counts = {c: {} for c in categories}
    examples: dict[str, list] = {}
    runs = 0
    for case in range(n_cases):
        category = schedule[case % len(schedule)]
        fmts = CATEGORY_FORMATS[category]
        fmt = fmts[(case // len(schedule)) % len(fmts)]
        folder = work / f"case{case}"
        folder.mkdir()
        path, what = change(rng, category, fmt, originals[fmt], folder)
        fp = fingerprint(path) if fmt != "bomb" else fp_original["bomb"]
        for index, args in enumerate(commands(fmt, path, folder / "out", case)):
            (folder / "out").mkdir(exist_ok=True)
            result = run_command(args)
            runs += 1
            output_original, inflated_original = intact_output(fmt, case, index) \
                if result["rc"] == 0 or fmt == "bomb" else (None, None)
            output = result_digest(args, folder / "out") if result["rc"] == 0 else None
            kind = classify(category, args[0], result, fp_original[fmt], fp, output, output_original)
            if fmt == "bomb" and result["inflated"] > inflated_original + BOMB_SLACK_BYTES:
                kind = "unbounded"
                result["err"] += f" [inflated {result['inflated']:,} bytes; viform's file: {inflated_original:,}]"
            if kind == "refused" and any(p.name in ("light.npz", "e.vfc", "d.npz", "d.zarr") or p.suffix == ".png"
                                         for p in (folder / "out").rglob("*")):
                kind = "partial-output"
            tally = counts[category]
            tally["runs"] = tally.get("runs", 0) + 1
            tally[kind] = tally.get(kind, 0) + 1
            left = leftovers(folder)
            if left:
                tally["leftovers"] = tally.get("leftovers", 0) + 1
                examples.setdefault("leftovers", []).append([category, what, args[0], left[:3]])
            interesting = kind not in ("identical", "refused") or category == "bomb"
            if interesting and len(examples.get(f"{category}/{kind}", [])) < 8:
                examples.setdefault(f"{category}/{kind}", []).append(
                    [fmt, what, " ".join(args[:1] + args[2:4]), result["rc"], round(result["cpu_s"], 2),
                     result["err"].strip()[-300:]])
            shutil.rmtree(folder / "out", ignore_errors=True)
        shutil.rmtree(folder, ignore_errors=True)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"cases": n_cases, "runs": runs, "counts": counts, "examples": examples, "peak_rss_mb": peak_mb}


def worker(seed: int, n_cases: int, result_file: str, bomb_mb: float) -> None:
    with tempfile.TemporaryDirectory(prefix="viform-fuzz-") as work:
        result = run_cases(seed, n_cases, Path(work), bomb_mb)
    Path(result_file).write_text(json.dumps(result, indent=1, default=str))


def run_worker(seed: int, n_cases: int, bomb_mb: float = BOMB_MB) -> dict:
    """Run the cases in a fresh process (so a crash, a hang or memory growth is seen from outside).

    Each command has its own limits (:func:`run_command`); the worker as a whole has none.
    """
    with tempfile.TemporaryDirectory(prefix="viform-fuzz-result-") as folder:
        result_file = Path(folder) / "result.json"
        proc = subprocess.run([sys.executable, __file__, "--worker", "--seed", str(seed), "--cases", str(n_cases),
                               "--bomb-mb", str(bomb_mb), "--result", str(result_file)], capture_output=True,
                              text=True, env={**os.environ, "VIFORM_DEBUG": ""})
        assert proc.returncode == 0, proc.stderr[-2000:]
        return json.loads(result_file.read_text())


def table(result: dict) -> str:
    """The counts as a table: runs / refused / identical / unverified / forged-accepted / silently
    wrong / internal errors / hangs / leftovers / other failures, per category."""
    columns = ["runs", "refused", "identical", "unverified", "forged-accepted", "silent", "internal", "hang",
               "leftovers", "other"]
    lines = ["| category | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for category, tally in result["counts"].items():
        other = sum(v for k, v in tally.items() if k not in columns and k != "unbounded")
        hangs = tally.get("hang", 0) + tally.get("unbounded", 0)
        row = [tally.get(c, 0) for c in columns[:7]] + [hangs, tally.get("leftovers", 0), other]
        lines.append(f"| {category} | " + " | ".join(str(v) for v in row) + " |")
    return "\n".join(lines)


# ---------------------------------------------------------------- the suite
def test_damaged_files_fail_cleanly():
    """30 seeded cases over the five categories × 2–5 commands: each run identical, refused in one
    line, or said unverified (forged values taken at their word are reviewed, not failed)."""
    result = run_worker(seed=11, n_cases=30, bomb_mb=BOMB_MB)
    failures = {f"{c}/{k}": v for c, tally in result["counts"].items() for k, v in tally.items()
                if k not in GOOD and k != "runs"}
    assert failures == {}, json.dumps(result["examples"], indent=1)[:6000]
    for category, tally in result["counts"].items():
        assert tally["runs"] > 0, category
        if category != "bomb":
            assert tally.get("refused", 0) > 0, (category, tally)  # the changes do damage
    assert result["counts"]["bomb"].get("identical", 0) == result["counts"]["bomb"]["runs"]
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
    parser.add_argument("--bomb-mb", type=float, default=BOMB_MB)
    parser.add_argument("--worker", action="store_true")
    parser.add_argument("--result")
    parser.add_argument("--json", help="also write the whole result (counts and examples) to this file")
    args = parser.parse_args()
    if args.worker:
        from viform._numba_cache import share_compiles

        share_compiles()  # the suite's own workers may be compiling the same kernels
        worker(args.seed, args.cases, args.result, args.bomb_mb)
        return
    started = time.perf_counter()
    result = run_worker(args.seed, args.cases, args.bomb_mb)
    result["elapsed_s"] = round(time.perf_counter() - started, 1)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1, default=str))
    print(json.dumps(result["examples"], indent=1, default=str)[:20000])
    print(f"{result['cases']} cases, {result['runs']} runs, {result['elapsed_s']} s, "
          f"peak {result['peak_rss_mb']:.0f} MB")
    print(table(result))


if __name__ == "__main__":
    main_cli()
