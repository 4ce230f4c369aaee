"""Every ``.vfc`` version: files written by the code of each earlier version decode exactly, today's
writer of each version gives the same bytes, each version's strict file is no larger than the one before, and
forged header fields are refused by name before anything is allocated from them."""

import json
import struct
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from viform._validate import ViformError
from viform.coding.aer_file import MAGIC, VERSION, CodedFile, encode_source
from viform.stream.container import SpikeStream

FIXTURES = Path(__file__).parent / "fixtures"
sys.path.insert(0, str(FIXTURES))
sys.path.insert(0, str(Path(__file__).parent))
from make_stream import (  # noqa: E402 -- the fixtures' own generator, importable by old trees too
    CLOCK_HZ,
    MODES,
    Q_ELECTRONS,
    SEGMENT_TICKS,
    fixture_spikes,
)

#: versions whose fixtures were written by the code of that version (make_stream.py)
FIXTURE_VERSIONS = (1, 2, 3, 4, 5, 6)


@pytest.fixture(scope="module")
def spikes():
    return fixture_spikes()


@pytest.mark.parametrize("mode", MODES)
def test_files_of_every_earlier_version_decode_exactly(spikes, mode):
    """The fixtures were written by the code of each version (v1: f5a62db^, v2: 8d83148^, v3: 608621c^,
    v4: 866098e, v5: 70d19ee, v6: the commit that made it the default); strict ones decode to the stream,
    lossy ones to the same spikes in every version (they code the same first-spike records), with the
    header's values."""
    decoded = []
    for v in FIXTURE_VERSIONS:
        cf = CodedFile(FIXTURES / f"v{v}_{mode}.vfc")
        assert (cf.version, cf.mode, cf.n_ticks, cf.height, cf.width) == (v, mode, *spikes.shape)
        assert (cf.clock_hz, cf.threshold_electrons, cf.start_time_s) == (CLOCK_HZ, Q_ELECTRONS, 0.25)
        decoded.append(cf.read_ticks(0, cf.n_ticks))
        assert cf.verify() == decoded[-1].sum()
    for d in decoded[1:]:
        assert np.array_equal(d, decoded[0])
    if mode == "strict":
        assert np.array_equal(decoded[0], spikes)
    else:  # lossy: spike counts per pixel kept exactly (seed 000 §5.2), times may move
        assert np.array_equal(decoded[0].sum(0), spikes.sum(0))
        assert not np.array_equal(decoded[0], spikes)


@pytest.mark.parametrize("mode", MODES)
def test_writers_of_every_version_keep_their_bytes(tmp_path, spikes, mode):
    """Today's writer of every version gives the bytes its fixture was written with by that version's own
    code (one shared range coder for every model, the split into one module per version: no byte moved);
    each version's strict file is no larger than the one before (version 5: than versions 3 and 4)."""
    stream = SpikeStream(spikes, CLOCK_HZ, Q_ELECTRONS, 0.25, {"fixture": "tests/coding/fixtures"})
    assert VERSION in FIXTURE_VERSIONS
    for v in FIXTURE_VERSIONS:
        path = tmp_path / f"v{v}.vfc"
        encode_source(stream, path, mode, segment_ticks=SEGMENT_TICKS, version=v)
        assert path.read_bytes() == (FIXTURES / f"v{v}_{mode}.vfc").read_bytes(), v
    if mode == "strict":
        size = {v: (FIXTURES / f"v{v}_strict.vfc").stat().st_size for v in FIXTURE_VERSIONS}
        assert size[5] <= min(size[3], size[4]) and size[6] <= size[5], size


def test_version_5_chooses_per_band(tmp_path):
    """A band of steady noise-free pixels (one interval for long runs) and a band of shot-noise pixels:
    version 5 codes them with different models and is smaller than both version 3 and version 4."""
    from viform.coding import vfc_v5
    from viform.coding.vfc_common import _PAYLOAD_HEAD

    rng = np.random.default_rng(7)
    t, h, w = 400, 96, 8
    out = np.zeros((t, h, w), bool)
    period = rng.integers(3, 9, (h, w))
    phase = rng.integers(0, 9, (h, w))
    ticks = np.arange(t)[:, None, None]
    out[:, :48] = ((ticks + phase) % period == 0)[:, :48]  # rows 0-47: exact periods (noise-free)
    rate = rng.uniform(0.08, 0.3, (48, w))  # rows 48-95: Gamma(Q = 30) intervals, shot noise
    charge = rng.uniform(0, 1, (48, w))
    for k in range(t):
        charge += rng.gamma(30 * rate, 1 / 30)
        out[k, 48:] = charge >= 1
        charge[charge >= 1] -= 1
    s = SpikeStream(out, 40_000.0, 30.0)
    sizes = {}
    for v in (3, 4, 5, 6):
        sizes[v] = encode_source(s, tmp_path / f"v{v}.vfc", segment_ticks=400, version=v)["bytes"]
    assert sizes[6] <= sizes[5] and np.array_equal(CodedFile(tmp_path / "v6.vfc").read_ticks(0, t), out), sizes
    payload = (tmp_path / "v5.vfc").read_bytes()
    cf = CodedFile(tmp_path / "v5.vfc")
    start = cf._index[0][0]
    models = vfc_v5.band_models(payload[start:start + cf._index[0][1]], 2)
    assert _PAYLOAD_HEAD.size and vfc_v5.MODEL_RECORDS in models and len(set(models)) == 2
    assert sizes[5] < min(sizes[3], sizes[4]), sizes
    assert np.array_equal(cf.read_ticks(0, t), out)
    # --fast: version 5 with the interval model on every band (version 4's work), still lossless, larger here
    fast = encode_source(s, tmp_path / "f.vfc", segment_ticks=400, fast=True)["bytes"]
    ff = CodedFile(tmp_path / "f.vfc")
    assert ff.version == 5
    fp = (tmp_path / "f.vfc").read_bytes()[ff._index[0][0]:ff._index[0][0] + ff._index[0][1]]
    assert vfc_v5.band_models(fp, 2) == [vfc_v5.MODEL_INTERVALS] * 2 and fast > sizes[5]
    assert np.array_equal(ff.read_ticks(0, t), out)
    # damage in either model's band: a one-line error or the exact spikes (every CRC still checks the rest)
    from test_aer_file import _assert_damage_is_refused_or_harmless

    _assert_damage_is_refused_or_harmless(tmp_path, payload, step=97, seed=5, flips=120)


def _reheader(data: bytes, version: int | None = None, **fields) -> bytes:
    """The file with header fields replaced (and the header CRC recomputed): a forgery a CRC cannot catch."""
    hlen = struct.unpack_from("<I", data, 10)[0]
    stored = struct.unpack_from("<H", data, 8)[0]
    head = data[18:18 + hlen]
    header = json.loads(zlib.decompress(head) if stored >= 6 else head)  # version 6: zlib-compressed header
    header.update(fields)
    v = stored if version is None else version
    head = json.dumps(header).encode()
    if v >= 6:
        head = zlib.compress(head, 9)
    return MAGIC + struct.pack("<HII", v, len(head), zlib.crc32(head)) + head + data[18 + hlen:]


@pytest.mark.parametrize("field, value", [
    ("clock_hz", 1e308), ("clock_hz", True), ("threshold_electrons", 1e308), ("start_time_s", 1e308),
    ("start_time_s", -1e308), ("height", 65536.0), ("k", 1e308),
])
def test_header_fields_out_of_bounds_are_refused_by_name(tmp_path, field, value):
    """A re-signed header field outside the documented bounds (those of a .dat sidecar) is refused at open,
    naming the field and the file."""
    path = tmp_path / "f.vfc"
    path.write_bytes(_reheader((FIXTURES / "v4_strict.vfc").read_bytes(), **{field: value}))
    with pytest.raises(ViformError, match=f"'{field}'") as info:
        CodedFile(path)
    assert "f.vfc" in str(info.value) and "\n" not in str(info.value)


def test_edited_version_is_refused(tmp_path):
    """The u16 version outside the checksum must agree with the header's (inside it): editing it to make an
    old reader's rules apply is refused."""
    path = tmp_path / "f.vfc"
    path.write_bytes(_swap_version(FIXTURES / "v3_strict.vfc", 2))
    with pytest.raises(ViformError, match="version"):
        CodedFile(path)
    path.write_bytes(_reheader((FIXTURES / "v3_strict.vfc").read_bytes(), format="something else"))
    with pytest.raises(ViformError, match="format"):
        CodedFile(path)


def _swap_version(path: Path, version: int) -> bytes:
    data = bytearray(path.read_bytes())
    struct.pack_into("<H", data, 8, version)
    return bytes(data)


def test_forged_height_is_bounded_before_allocating(tmp_path):
    """The 24 KB file that once drove ``viform decode`` to 6 GB: a header re-signed to height 65,536.
    A banded (version 5) file is refused at open (a segment's pixel-ticks are bounded); a version-3 file
    is refused while decoding with little memory (blocks are sized by pixels, not by ticks)."""
    import tracemalloc

    stream = SpikeStream(fixture_spikes(), CLOCK_HZ, Q_ELECTRONS)
    encode_source(stream, tmp_path / "g.vfc")
    path = tmp_path / "h.vfc"
    path.write_bytes(_reheader((tmp_path / "g.vfc").read_bytes(), height=65536, width=48))
    with pytest.raises(ViformError, match="segment_ticks"):
        CodedFile(path)
    path.write_bytes(_reheader((FIXTURES / "v3_strict.vfc").read_bytes(), height=65536, width=10))
    tracemalloc.start()
    try:
        with pytest.raises(ViformError, match="h.vfc"):
            CodedFile(path).verify()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 400 << 20  # the per-pixel state of 655,360 pixels (~110 MB), no tick × pixel array


def test_writer_never_writes_what_the_reader_refuses(tmp_path):
    """A stream whose clock (or a k) lies outside the header bounds is refused before the file is made."""
    with pytest.raises(ViformError, match="clock_hz"):
        encode_source(SpikeStream(np.zeros((10, 2, 2), bool), 1e13), tmp_path / "c.vfc")
    with pytest.raises(ViformError, match="k = "):
        encode_source(SpikeStream(np.zeros((10, 2, 2), bool), 1e3, 100.0), tmp_path / "k.vfc", "statistical", k=2e6)
    assert not list(tmp_path.iterdir())


def _runs_of_widths(rng, t, h, w, widths=(5, 60), runs=(2, 5)) -> np.ndarray:
    """Pixels that hold a random width for a short run of spikes, then jump to another (what records code well)."""
    out = np.zeros((t, h, w), bool)
    for i in range(h):
        for j in range(w):
            tick = int(rng.integers(0, 10))
            while tick < t:
                width = int(rng.integers(*widths))
                for _ in range(int(rng.integers(*runs))):
                    if tick >= t:
                        break
                    out[tick, i, j] = True
                    tick += width
    return out


def test_version_6_codes_records_where_smaller(tmp_path, monkeypatch):
    """A band of shot-noise pixels (Gamma intervals, Q = 30) and a band of pixels jumping between held widths:
    version 6 codes the first with the tick model and the second as records (after its first segment), the
    state carried across the switch; exact, no larger than version 5, the same bytes on 1 or 2 threads, and
    damage gives a one-line error or the exact spikes."""
    from test_aer_file import _assert_damage_is_refused_or_harmless

    from viform.coding import vfc_v6

    rng = np.random.default_rng(11)
    t, h, w = 400, 96, 8
    out = np.zeros((t, h, w), bool)
    rate = rng.uniform(0.08, 0.3, (48, w))
    charge = rng.uniform(0, 1, (48, w))
    for k in range(t):
        charge += rng.gamma(30 * rate, 1 / 30)
        out[k, :48] = charge >= 1
        charge[charge >= 1] -= 1
    out[:, 48:] = _runs_of_widths(rng, t, 48, w)
    s = SpikeStream(out, 40_000.0, 30.0)
    sizes = {v: encode_source(s, tmp_path / f"v{v}.vfc", segment_ticks=100, version=v)["bytes"] for v in (5, 6)}
    assert sizes[6] <= sizes[5], sizes
    cf = CodedFile(tmp_path / "v6.vfc")
    data = (tmp_path / "v6.vfc").read_bytes()
    models = [vfc_v6.band_models(data[off:off + length], 2) for off, length, _ in cf._index]
    assert [m[0] for m in models] == [vfc_v6.MODEL_TICKS] * 4, models
    assert vfc_v6.MODEL_RECORDS in [m[1] for m in models], models
    assert np.array_equal(cf.read_ticks(0, t), out)
    assert np.array_equal(cf.read_ticks(150, 333), out[150:333])
    monkeypatch.setenv("VIFORM_THREADS", "1")
    encode_source(s, tmp_path / "one.vfc", segment_ticks=100, version=6)
    assert (tmp_path / "one.vfc").read_bytes() == data
    _assert_damage_is_refused_or_harmless(tmp_path, data, step=53, seed=6, flips=150)


def test_forged_records_band_count_is_not_allocated_up_front():
    """A version-6 segment of a few bytes whose one records band claims every pixel-tick of the largest
    segment (2^28 spikes: 2 GiB of ticks) is refused as damaged with memory of the order of its per-pixel
    state, not of the stated count: the decoder never sizes its tick array by a count its bytes cannot hold."""
    import tracemalloc

    from viform.coding import vfc_v6
    from viform.coding.vfc_v5 import _varint

    height = width = 256
    n_ticks = 4096  # 2^28 pixel-ticks: the most a segment's header may state
    spikes = n_ticks * height * width
    data = b"\x00" * 16
    payload = (bytes([vfc_v6._FLAG_BANDS6]) + _varint(0) + _varint(n_ticks) + _varint(spikes) + _varint(len(data))
               + _varint(spikes * 4 + vfc_v6.MODEL_RECORDS) + _varint(1) + data)
    tracemalloc.start()
    try:
        with pytest.raises(ViformError, match="damaged"):
            vfc_v6.decode_payload(payload, vfc_v6.BandState(height, width, height), 0, n_ticks)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 256 << 20  # the stated count alone would be 2,048 MiB
