"""Integrity no edit can switch off (issue 39.1–39.5): what an edit of a file can and cannot do.

- An ``.npz`` header that keeps any field only viform writes (its provenance included) must be
  whole; with the header gone the file is another tool's: read *unverified*, said once, and
  ``verify`` exits 3, never 0.
- A ``.dat`` sidecar stripped of every viform field is another tool's: the same.
- Bytes before or after a zip archive are refused (the ``.vfc`` rule).
- A partial read of another tool's huge ``.npz`` member costs what it reads, not the member.
- Edits whose digest was recomputed still meet the checks that need no key: padding bits zero,
  stored and declared widths agreeing, no unknown field, no ``null`` where viform writes a number.
"""

from __future__ import annotations

import io
import json
import struct
import warnings
import zipfile
import zlib
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from viform._validate import UnverifiedDataWarning, ViformError
from viform.cli import main
from viform.stream import npz as npz_module
from viform.stream.checksums import header_digest
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes
from viform.stream.sidecar import DIGEST_KEY, _digest, sidecar_path
from viform.stream.zarr_store import _header_digest

T, H, W = 160, 8, 16
FLIPPED = ((15, 3, 5), (16, 3, 5), (17, 3, 5))


def stream():
    return SpikeStream(np.random.default_rng(4).random((T, H, W)) < 0.2, 40_000.0, 60.0)


def run(*args) -> tuple[int, str, str]:
    err, out = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def rewrite_npz(path, change):
    with np.load(path) as data:
        members = {k: data[k] for k in data.files}
    change(members)
    with open(path, "wb") as f:
        np.savez(f, **members)  # the zip's own CRC-32s match the edited members


def flip_spikes(members):
    spk = members["spk"].copy()
    for t, r, c in FLIPPED:
        spk[t, r, c] ^= 1
    members["spk"] = spk


# ---------------------------------------------------------------- 39.1 .npz
def test_npz_header_without_its_integrity_fields_is_damaged(tmp_path):
    """The campaign's edit: the six integrity fields deleted (provenance kept), one spike flipped, re-zipped."""
    path = save_spikes(tmp_path / "s.npz", stream())

    def strip(members):
        header = json.loads(str(members["viform_header"]))
        for key in ("format", "version", "member_bytes", "block_bytes", "block_crc32", "header_blake2b"):
            header.pop(key)
        members["viform_header"] = np.array(json.dumps(header))
        flip_spikes(members)

    rewrite_npz(path, strip)
    with pytest.raises(ViformError, match="holds viform's field 'viform_version'.*damaged or was edited"):
        open_spikes(path)
    for args in (["verify", path], ["reconstruct", path, "--at", "0.0004", "--out", tmp_path / "r"]):
        rc, _, err = run(*args)
        assert rc == 2 and err.count("\n") == 1 and "damaged or was edited" in err, err
    assert not (tmp_path / "r").exists()


def test_npz_without_its_header_is_read_unverified_and_never_verified(tmp_path):
    path = save_spikes(tmp_path / "s.npz", stream())

    def strip(members):
        del members["viform_header"]
        flip_spikes(members)

    rewrite_npz(path, strip)
    source = open_spikes(path)
    assert not source.checked
    with pytest.warns(UnverifiedDataWarning, match="s.npz' holds no viform checksums") as caught:
        source.read_ticks(0, 4)
        source.read_ticks(4, 8)
    assert len(caught) == 1  # said once
    rc, out, err = run("verify", path)
    assert rc == 3 and "not verified" in out and err == "", (rc, out, err)
    rc, out, err = run("reconstruct", path, "--at", "0.0004", "--out", tmp_path / "r")
    warned = [line for line in err.splitlines() if "read unverified" in line]
    assert rc == 0 and len(warned) == 1 and warned[0].startswith("viform: warning: "), err
    rc, out, _ = run("info", path)
    assert rc == 0 and "verified: no" in out


# ---------------------------------------------------------------- 39.2 .dat
def test_dat_sidecar_without_any_viform_field_is_never_verified(tmp_path):
    path = save_spikes(tmp_path / "s.dat", stream())
    side = json.loads(sidecar_path(path).read_text())
    foreign = {k: v for k, v in side.items()
               if k not in ("format", "version", DIGEST_KEY, "blake2b", "data_bytes", "block_bytes", "block_crc32",
                            "viform_version", "command_line", "utc_date")}
    sidecar_path(path).write_text(json.dumps(foreign))
    raw = bytearray(path.read_bytes())
    raw[16 * 16 + 3] ^= 0x10  # a spike of tick 16
    path.write_bytes(bytes(raw))
    rc, out, err = run("verify", path)
    assert rc == 3 and "readable, but not verified" in out and "no viform checksums" in out, (rc, out, err)
    rc, out, err = run("reconstruct", path, "--at", "0.0004", "--out", tmp_path / "r")
    assert rc == 0 and sum("read unverified" in line for line in err.splitlines()) == 1, err
    with pytest.warns(UnverifiedDataWarning, match="holds no viform checksums"):
        open_spikes(path).read_ticks(0, 1)


def test_dat_sidecar_keeping_its_provenance_is_damaged(tmp_path):
    path = save_spikes(tmp_path / "s.dat", stream())
    side = json.loads(sidecar_path(path).read_text())
    for key in ("format", "version", DIGEST_KEY, "blake2b", "data_bytes", "block_bytes", "block_crc32",
                "viform_version"):
        side.pop(key)
    sidecar_path(path).write_text(json.dumps(side))
    with pytest.raises(ViformError, match="holds viform's field 'command_line'"):
        open_spikes(path)


def test_verify_says_what_a_sidecar_lacks(tmp_path):
    """``{}`` as sidecar: the message says the sidecar does not give the size (not that it is absent)."""
    path = save_spikes(tmp_path / "d.dat", stream())
    sidecar_path(path).write_text("{}")
    rc, _, err = run("verify", path)
    assert rc == 2 and "its sidecar 'd.dat.json' does not give height and width" in err and "absent" not in err
    assert "--height 250 --width 400" in err
    sidecar_path(path).unlink()
    rc, _, err = run("verify", path)
    assert rc == 2 and "'d.dat.json' (the sidecar viform writes) is absent" in err


# ---------------------------------------------------------------- 39.3 zip framing
@pytest.mark.parametrize("kind", ["junk after", "itself after", "junk before", "zip comment"])
@pytest.mark.parametrize("name", ["s.npz", "zoo.npz"])
def test_bytes_around_a_zip_are_refused(tmp_path, name, kind):
    path = tmp_path / name
    if name == "s.npz":
        save_spikes(path, stream())
    else:
        np.savez_compressed(path, spk=stream().spikes.astype(np.uint8))
    data = path.read_bytes()
    if kind == "zip comment":  # a comment is part of the end record: allowed
        with zipfile.ZipFile(path, "a") as zf:
            zf.comment = b"written by hand"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert open_spikes(path).read_ticks(0, T).sum() == stream().spikes.sum()
        # viform's own file stays verified; another tool's is read unverified, and says so once
        assert [w.category for w in caught] == ([] if name == "s.npz" else [UnverifiedDataWarning])
        return
    path.write_bytes({"junk after": data + b"junk", "itself after": data + data, "junk before": b"MZ" + data}[kind])
    with pytest.raises(ViformError, match="damaged or was edited: it holds .*bytes (after|before)"):
        open_spikes(path)
    rc, _, err = run("verify", path)
    assert rc == 2 and err.count("\n") == 1


# ---------------------------------------------------------------- 39.4 bounded partial reads
def _bomb(path, n_ticks, height=64, width=128):
    """Another tool's .npz: random spikes in the first 200 ticks, zeros after (deflates to almost nothing)."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|u1", "fortran_order": False,
                                                  "shape": (n_ticks, height, width)})
    busy = (np.random.default_rng(1).random((200, height, width)) < 0.2).astype(np.uint8)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        with zf.open("spk.npy", "w", force_zip64=True) as fp:
            fp.write(header.getvalue())
            fp.write(busy.tobytes())
            zeros = bytes(height * width * 1024)
            left = n_ticks - 200
            while left > 0:
                fp.write(zeros[: min(1024, left) * height * width])
                left -= 1024
    return busy


def test_partial_read_of_a_huge_foreign_member_inflates_only_what_it_reads(tmp_path, monkeypatch):
    """A 70 kB file holding 67 MB of spikes: reading ticks 10–20 inflates about those ticks' bytes.

    The member is above :data:`WHOLE_CHECK_BYTES`, so its zip CRC-32 is checked only by a read to
    its end (``verify``); the read says the data is unverified, naming the member's size.
    """
    path = tmp_path / "bomb.npz"
    busy = _bomb(path, 8192)
    monkeypatch.setattr(npz_module, "WHOLE_CHECK_BYTES", 32 << 20)
    assert path.stat().st_size < 1e6
    inflated = []
    real = zipfile.ZipExtFile.read

    def counted(self, n=-1):
        data = real(self, n)
        inflated.append(len(data))
        return data

    monkeypatch.setattr(zipfile.ZipExtFile, "read", counted)
    source = open_spikes(path)
    with pytest.warns(UnverifiedDataWarning, match="0.0671 GB spike member is checked only by a read to its end"):
        ticks = source.read_ticks(10, 20)
    assert np.array_equal(ticks, busy[10:20].astype(bool))
    assert sum(inflated) < 2 * 20 * 64 * 128 + 4096  # ticks 0–19 and the .npy header, not 67 MB
    monkeypatch.setattr(npz_module, "WHOLE_CHECK_BYTES", 1 << 30)  # a small member is checked whole first
    inflated.clear()
    with pytest.warns(UnverifiedDataWarning, match="zip CRC-32 of its spikes is checked"):
        open_spikes(path).read_ticks(10, 20)
    assert sum(inflated) >= 8192 * 64 * 128


def test_damage_past_a_partial_read_is_caught_when_a_read_reaches_it(tmp_path, monkeypatch):
    """Bounded reads of a big foreign member still check its zip CRC-32 at the end (and verify reads to it)."""
    monkeypatch.setattr(npz_module, "WHOLE_CHECK_BYTES", 1 << 10)
    path = tmp_path / "zoo.npz"
    spikes = stream().spikes.astype(np.uint8)
    np.savez(path, spk=spikes)  # stored (not deflated): a flipped byte is a wrong spike, not a zlib error
    raw = bytearray(path.read_bytes())
    offset = raw.index(spikes.tobytes()[-200:]) + 100
    raw[offset] ^= 1
    path.write_bytes(bytes(raw))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnverifiedDataWarning)
        assert open_spikes(path).read_ticks(0, 4).shape == (4, H, W)  # early ticks: unchecked, and said so
        with pytest.raises(ViformError, match="zoo.npz.*damaged"):
            open_spikes(path).read_ticks(0, T)
    rc, _, err = run("verify", path)
    assert rc == 2 and "damaged" in err


def test_an_interrupted_command_says_what_it_kept(tmp_path, monkeypatch):
    """reconstruct has written its image and light.npz; Ctrl-C while it prints its summary."""
    import viform.cli.reconstruct as reconstruct_cli

    path = save_spikes(tmp_path / "s.dat", stream())
    real_echo = reconstruct_cli.click.echo

    def echo(message=None, *args, **kwargs):
        if message and str(message).startswith("wrote "):
            raise KeyboardInterrupt
        return real_echo(message, *args, **kwargs)

    monkeypatch.setattr(reconstruct_cli.click, "echo", echo)
    rc, _, err = run("reconstruct", path, "--at", "0.002", "--out", tmp_path / "r")
    kept = sorted(p.name for p in (tmp_path / "r").iterdir())
    assert rc == 130 and len(kept) == 2 and "light.npz" in kept
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("viform: interrupted; kept 2 complete file(s)"), err
    assert str(tmp_path / "r" / "light.npz") in lines[0]


# ---------------------------------------------------------------- 39.5 checks that need no key
def test_zarr_width_edited_narrower_is_caught_by_its_padding_bits(tmp_path):
    """16 columns stored, 13 declared (the same packed width), digest recomputed: spikes in the
    columns cut off sit in the padding bits, which viform writes as zero."""
    path = save_spikes(tmp_path / "s.zarr", stream())
    meta_file = path / "zarr.json"
    meta = json.loads(meta_file.read_text())
    header = meta["attributes"]["viform"]
    header["width"] = 13
    header["header_blake2b"] = _header_digest(header)
    meta_file.write_text(json.dumps(meta))
    with pytest.raises(ViformError, match="past the declared width of 13 columns"):
        open_spikes(path).read_ticks(0, T)


def test_zarr_narrow_stream_reads_back(tmp_path):
    """The padding check passes viform's own odd widths."""
    spikes = np.random.default_rng(0).random((50, 3, 13)) < 0.5
    back = open_spikes(save_spikes(tmp_path / "n.zarr", SpikeStream(spikes, 40_000.0)))
    assert np.array_equal(back.read_ticks(0, 50), spikes)


def _edit_header(path, fmt, field, value):
    if fmt == "dat":
        side = json.loads(sidecar_path(path).read_text())
        side[field] = value
        side[DIGEST_KEY] = _digest(side)
        sidecar_path(path).write_text(json.dumps(side))
    elif fmt == "zarr":
        meta = json.loads((path / "zarr.json").read_text())
        meta["attributes"]["viform"][field] = value
        meta["attributes"]["viform"]["header_blake2b"] = _header_digest(meta["attributes"]["viform"])
        (path / "zarr.json").write_text(json.dumps(meta))
    else:
        def change(members):
            header = json.loads(str(members["viform_header"]))
            header[field] = value
            header["header_blake2b"] = header_digest(header)
            members["viform_header"] = np.array(json.dumps(header))

        rewrite_npz(path, change)


@pytest.mark.parametrize("fmt, field, value, needle", [
    ("dat", "clock_hz", None, "'clock_hz' is null"),
    ("dat", "n_ticks", None, "'n_ticks' is null"),
    ("dat", "stored_width", 24, "'stored_width' = 24 differs from 'width'"),
    ("npz", "clock_hz", None, "'clock_hz' is null"),
    ("npz", "x_unknown", 1, "field 'x_unknown' is not one this viform writes"),
    ("npz", "rows", "bottom-up", "viform stores .npz spikes upright"),
    ("zarr", "start_time_s", None, "'start_time_s' is missing"),
    ("zarr", "x_unknown", 1, "field 'x_unknown' is not one this viform writes"),
])
def test_edits_with_a_recomputed_digest_meet_the_checks_that_need_no_key(tmp_path, fmt, field, value, needle):
    path = save_spikes(tmp_path / f"s.{fmt}", stream())
    _edit_header(path, fmt, field, value)
    with pytest.raises(ViformError, match=needle):
        open_spikes(path).read_ticks(0, 4)


def test_a_dat_sidecar_may_hold_fields_of_its_own(tmp_path):
    """.dat sidecars carry records beside the stream (a dataset's); those are not refused."""
    path = save_spikes(tmp_path / "s.dat", stream())
    _edit_header(path, "dat", "dataset", {"clip": "c1"})
    assert open_spikes(path).verify()["verified"]


def _forge_vfc(path, field, value):
    """Edit one header field and recompute the header's CRC-32, as a careful forger would (version 6
    headers are zlib-compressed JSON: unpacked and packed again)."""
    from viform.coding import vfc_v6

    raw = path.read_bytes()
    version, hlen, _ = struct.unpack_from("<HII", raw, 8)
    head = raw[18:18 + hlen]
    header = json.loads(vfc_v6.unpack_header(head) if version >= 6 else head)
    header[field] = value
    head = json.dumps(header).encode()
    if version >= 6:
        head = vfc_v6.pack_header(head)
    path.write_bytes(raw[:8] + struct.pack("<HII", version, len(head), zlib.crc32(head)) + head + raw[18 + hlen:])


@pytest.mark.parametrize("mode, field, value, needle", [
    ("strict", "x_unknown", 1, "field 'x_unknown' is not one this viform writes"),
    ("statistical", "threshold_electrons", None, "'threshold_electrons' = None is not allowed: the statistical"),
])
def test_vfc_header_edits_with_a_recomputed_crc_are_refused(tmp_path, mode, field, value, needle):
    from viform.coding.aer_file import CodedFile, encode_source

    path = tmp_path / "c.vfc"
    encode_source(stream(), path, mode, segment_ticks=64)
    CodedFile(path).verify()
    _forge_vfc(path, field, value)
    with pytest.raises(ViformError, match=needle):
        CodedFile(path)


def test_every_vfc_version_writes_only_known_header_fields(tmp_path):
    """The reader's list of fields (others refused) holds what every writer writes."""
    from viform.coding.aer_file import HEADER_FIELDS, SUPPORTED_VERSIONS, CodedFile, encode_source

    for version in SUPPORTED_VERSIONS:
        for mode in ("strict", "statistical"):
            path = tmp_path / f"v{version}{mode}.vfc"
            encode_source(stream(), path, mode, segment_ticks=64, version=version)
            assert set(CodedFile(path).header) <= set(HEADER_FIELDS), (version, mode)


def test_info_does_not_call_a_vfc_verified_that_it_has_not_decoded(tmp_path):
    """A header edited to another width, its CRC-32 recomputed: every checksum still matches, only a
    decode shows the damage. ``info`` (no decode) says not verified; ``verify`` refuses the file."""
    from viform.coding.aer_file import encode_source

    path = tmp_path / "c.vfc"
    encode_source(stream(), path, "strict", segment_ticks=64)
    rc, out, _ = run("info", path)
    assert rc == 0 and "verified: no" in out and "run viform verify" in out
    _forge_vfc(path, "width", 8)
    rc, out, _ = run("info", path)
    assert rc == 0 and "verified: no" in out
    rc, _, err = run("verify", path)
    assert rc == 2 and "c.vfc" in err and err.count("\n") == 1
