"""Every read checks exactly the bytes it uses; integrity cannot be edited away (issue 26).

Block checksums are made small here (``small_blocks``) so a file of a few kB has many blocks
and a partial read touches only some, as a real file's read does with 1 MiB blocks.
"""

import json
import zipfile

import numpy as np
import pytest

from viform._validate import ViformError
from viform.stream import checksums
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes, verify_spikes
from viform.stream.sidecar import DIGEST_KEY, _digest, sidecar_path

T, H, W = 400, 8, 16  # 16 bytes a tick in .dat, 128 in .npz


@pytest.fixture
def small_blocks(monkeypatch):
    monkeypatch.setattr(checksums, "MIN_BLOCK_BYTES", 512)


def stream():
    return SpikeStream(np.random.default_rng(3).random((T, H, W)) < 0.3, 40_000.0, 50.0)


def flip(path, offset):
    raw = bytearray(path.read_bytes())
    raw[offset] ^= 0x20
    path.write_bytes(bytes(raw))


# ---------------------------------------------------------------- block manifests
def test_block_crcs_match_whole_blocks_and_reader_checks_each():
    data = np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes()
    crcs = checksums.BlockCrcs(1024)
    for piece in (data[:7], data[7:3000], data[3000:]):  # any split gives the same blocks
        crcs.update(piece)
    manifest = crcs.finish()
    assert len(manifest) == 5
    reads = []

    def read_raw(offset, count):
        reads.append(offset)
        return data[offset:offset + count]

    reader = checksums.BlockReader(manifest, 1024, len(data), read_raw, "'x'")
    assert reader.read(1000, 100) == data[1000:1100] and reads == [0, 1024]
    assert reader.read(1030, 10) == data[1030:1040] and reads == [0, 1024]  # cached, already checked
    broken = checksums.BlockReader(manifest, 1024, len(data), lambda o, c: bytes(c), "'x'")
    with pytest.raises(ViformError, match="block 2 .*differs from its CRC-32"):
        broken.read(2100, 5)
    assert checksums.block_bytes_for(10) == checksums.MIN_BLOCK_BYTES
    assert -(-(1 << 40) // checksums.block_bytes_for(1 << 40)) <= checksums.MAX_BLOCKS


@pytest.mark.parametrize("name", ["s.dat", "s.npz"])
def test_partial_read_checks_the_blocks_it_uses(tmp_path, small_blocks, name):
    """Damage late in the file: early ticks still read (and are right); the damaged ones never."""
    s = stream()
    path = save_spikes(tmp_path / name, s)
    if name.endswith(".npz"):  # stored uncompressed, so a byte of the archive is a byte of the spikes
        with np.load(path) as data:
            members = {k: data[k] for k in data.files}
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
            for k, v in members.items():
                with zf.open(k + ".npy", "w") as fp:
                    np.lib.format.write_array(fp, v)
        start = path.read_bytes().find(b"spk.npy") + 200
        offset = start + 300 * H * W  # inside tick ~300
    else:
        offset = 300 * H * W // 8
    flip(path, offset)
    source = open_spikes(path)
    assert np.array_equal(source.read_ticks(0, 50), s.spikes[:50])
    with pytest.raises(ViformError, match="damaged"):
        source.read_ticks(280, 320)
    with pytest.raises(ViformError, match="damaged"):
        verify_spikes(path)


# ---------------------------------------------------------------- .dat sidecars
def test_deleting_sidecar_checksums_does_not_turn_checks_off(tmp_path):
    path = save_spikes(tmp_path / "e.dat", stream())
    flip(path, 100)
    side = json.loads(sidecar_path(path).read_text())
    for dropped in (["blake2b", DIGEST_KEY], ["block_crc32", "block_bytes", DIGEST_KEY], [DIGEST_KEY]):
        edited = {k: v for k, v in side.items() if k not in dropped}
        sidecar_path(path).write_text(json.dumps(edited))
        with pytest.raises(ViformError, match="damaged or was edited"):
            open_spikes(path)
    edited = {k: v for k, v in side.items() if k not in ("blake2b", DIGEST_KEY)}
    sidecar_path(path).write_text(json.dumps({**edited, "height": 16, "width": 96}))  # the size edited too
    with pytest.raises(ViformError, match="damaged or was edited"):
        open_spikes(path)
    # viform's markers gone too: another tool's sidecar, read as such and never reported verified
    foreign = {k: side[k] for k in ("height", "width", "clock_hz", "threshold_electrons", "rows")}
    sidecar_path(path).write_text(json.dumps(foreign))
    source = open_spikes(path)
    assert not source.checked and not source.verify()["verified"]


def test_sidecar_version_1_checks_the_whole_file_before_first_read(tmp_path):
    path = save_spikes(tmp_path / "v1.dat", stream())
    side = json.loads(sidecar_path(path).read_text())
    for k in ("block_crc32", "block_bytes"):
        side.pop(k)
    side["version"] = 1
    side[DIGEST_KEY] = _digest(side)
    sidecar_path(path).write_text(json.dumps(side))
    assert open_spikes(path).checked
    flip(path, path.stat().st_size - 1)
    with pytest.raises(ViformError, match="BLAKE2b"):
        open_spikes(path).read_ticks(0, 1)


# ---------------------------------------------------------------- .npz
def rewrite_npz(path, change):
    with np.load(path) as data:
        members = {k: data[k] for k in data.files}
    change(members)
    with open(path, "wb") as f:
        np.savez(f, **members)


@pytest.mark.parametrize("dropped", [["block_crc32"], ["header_blake2b"], ["format", "version"]])
def test_npz_header_with_checksums_removed_is_damaged(tmp_path, dropped):
    path = save_spikes(tmp_path / "s.npz", stream())

    def drop(members):
        header = json.loads(str(members["viform_header"]))
        for k in dropped:
            header.pop(k)
        members["viform_header"] = np.array(json.dumps(header))

    rewrite_npz(path, drop)
    with pytest.raises(ViformError, match="damaged or was edited|not supported"):
        open_spikes(path)


def test_other_tools_npz_is_checked_before_a_partial_read(tmp_path):
    """No block checksums: the member's zip CRC-32 is checked by a pass before the first image."""
    path = tmp_path / "zoo.npz"
    np.savez_compressed(path, spk=stream().spikes.astype(np.uint8))
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0x08  # late in the compressed spikes
    path.write_bytes(bytes(raw))
    with pytest.raises(ViformError, match="zoo.npz"):
        open_spikes(path).read_ticks(0, 2)


@pytest.mark.parametrize("name, value", [("clock_hz", 1e-300), ("threshold_electrons", 1e-300),
                                         ("clock_hz", True), ("start_time_s", 1e300), ("clock_hz", [1.0, 2.0])])
def test_other_tools_npz_metadata_passes_the_header_bounds(tmp_path, name, value):
    path = tmp_path / "zoo.npz"
    np.savez(path, spk=np.zeros((10, 4, 8), np.uint8), **{name: np.asarray(value)})
    with pytest.raises(ViformError, match=name):
        open_spikes(path)


def test_npz_with_two_members_of_one_name_is_refused(tmp_path):
    path = tmp_path / "zoo.npz"
    np.savez(path, spk=np.zeros((10, 4, 8), np.uint8))
    with zipfile.ZipFile(path, "a") as zf, pytest.warns(UserWarning, match="Duplicate"):
        zf.writestr("spk.npy", b"x")
    with pytest.raises(ViformError, match="several members named 'spk.npy'"):
        open_spikes(path)


# ---------------------------------------------------------------- zarr, empty streams
def test_zarr_version_edited_down_is_damaged(tmp_path):
    path = save_spikes(tmp_path / "s.zarr", stream())
    meta_file = path / "zarr.json"
    meta = json.loads(meta_file.read_text())
    meta["attributes"]["viform"]["version"] = 1
    meta_file.write_text(json.dumps(meta))
    with pytest.raises(ViformError, match="damaged or was edited"):
        open_spikes(path)
    header = meta["attributes"]["viform"]
    for k in ("chunks", "chunk_ticks", "header_blake2b", "n_ticks", "viform_version", "utc_date", "command_line"):
        header.pop(k)
    meta_file.write_text(json.dumps(meta))
    with pytest.raises(ViformError, match="without checksums"):  # a genuine version 1 store: not verifiable
        open_spikes(path)


@pytest.mark.parametrize("name", ["e.dat", "e.npz", "e.zarr"])
def test_empty_stream_is_one_clear_error(tmp_path, name):
    path = tmp_path / name
    if name.endswith(".dat"):
        path.write_bytes(b"")
        match = "no whole frame"
    else:
        save_spikes(path, SpikeStream(np.zeros((0, 4, 8), bool), 40_000.0))
        match = "empty stream"
    with pytest.raises(ViformError, match=match):
        open_spikes(path, 4, 8) if name.endswith(".dat") else open_spikes(path)


@pytest.mark.parametrize("member", ["spk", "clock_hz"])
def test_damaged_npy_header_is_refused_not_skipped(tmp_path, member):
    """numpy parses .npy headers with tokenize/ast: their errors are damage, and a clock that
    cannot be read is never replaced by the default one."""
    value = np.zeros((10, 4, 8), np.uint8) if member == "spk" else np.zeros((1, 1))
    raw = _npy(value)
    shape = repr(value.shape).encode()
    raw = raw.replace(shape, shape[:-1] + b" ", 1)  # an unclosed parenthesis, same length
    path = tmp_path / "zoo.npz"
    with zipfile.ZipFile(path, "w") as zf:
        if member != "spk":
            zf.writestr("spk.npy", _npy(np.zeros((10, 4, 8), np.uint8)))
        zf.writestr(f"{member}.npy", raw)
    with pytest.raises(ViformError, match=member):
        open_spikes(path)


def _npy(array) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()


def test_dat_words_are_the_checked_bytes_padded_to_words(tmp_path, small_blocks):
    """read_packed_words: read_packed's rows zero-padded to 64-bit words, copied once from the checked blocks
    (13-byte ticks in 512-byte blocks: rows cross blocks); damage is found in the blocks a read uses."""
    from viform.stream.sidecar import sidecar_path
    from viform.vision.tracking import _words

    s = SpikeStream(np.random.default_rng(5).random((T, 4, 26)) < 0.3, 40_000.0, 50.0)
    path = save_spikes(tmp_path / "odd.dat", s)
    source = open_spikes(path)
    assert source.frame_bytes == 13
    for a, b in [(0, 1), (0, T), (3, 4), (39, 40), (39, 79), (100, 357), (T - 1, T), (5, 5)]:
        words = source.read_packed_words(a, b)
        assert words.dtype == np.uint64 and words.shape == (b - a, 2) and words.flags.c_contiguous
        np.testing.assert_array_equal(words, _words(source.read_packed(a, b)))
    # into a buffer of the caller's (a reused one: stale bits and padding overwritten), its first rows returned
    out = np.full((400, 2), np.uint64(0xFFFFFFFFFFFFFFFF))
    for a, b in [(0, 400), (3, 4), (100, 357), (5, 5)]:
        words = source.read_packed_words(a, b, out=out)
        assert words.shape == (b - a, 2) and (a == b or np.shares_memory(words, out))
        np.testing.assert_array_equal(words, _words(source.read_packed(a, b)))
    for bad in (np.zeros((10, 2), np.uint64), np.zeros((400, 3), np.uint64), np.zeros((400, 2), np.int64),
                np.zeros((2, 400), np.uint64).T):
        with pytest.raises(ViformError, match="out must be"):
            source.read_packed_words(0, 20, out=bad)
    flip(path, 300 * 13)
    source = open_spikes(path)
    np.testing.assert_array_equal(source.read_packed_words(0, 50), _words(source.read_packed(0, 50)))
    with pytest.raises(ViformError, match="damaged"):
        source.read_packed_words(280, 320)
    path = save_spikes(tmp_path / "plain.dat", s)
    sidecar_path(path).unlink()  # no checksums: read as stored
    source = open_spikes(path, height=4, width=26)
    with pytest.warns(UserWarning):
        np.testing.assert_array_equal(source.read_packed_words(7, 333), _words(source.read_packed(7, 333)))
