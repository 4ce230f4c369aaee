"""Zarr stores are checked: missing or damaged chunks and forged attributes are one-line errors."""

import json

import numpy as np
import pytest

from viform._validate import ViformError
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes, verify_spikes
from viform.stream.zarr_store import _header_digest


def store(tmp_path, t=40):
    s = SpikeStream(np.random.default_rng(2).random((t, 6, 12)) < 0.3, 20_000.0, 30.0)
    return save_spikes(tmp_path / "s.zarr", s, block_ticks=8), s


def edit_header(path, change, redigest=True):
    meta_file = path / "zarr.json"
    meta = json.loads(meta_file.read_text())
    header = meta["attributes"]["viform"]
    change(header)
    if redigest:
        header["header_blake2b"] = _header_digest(header)
    meta_file.write_text(json.dumps(meta))


def test_round_trip_and_verify(tmp_path):
    path, s = store(tmp_path)
    back = open_spikes(path)
    assert back.checked and np.array_equal(back.read_ticks(3, 37), s.spikes[3:37])
    assert verify_spikes(path)["verified"]


def test_missing_chunk_is_an_error_never_zeros(tmp_path):
    path, _ = store(tmp_path)
    (path / "c" / "2" / "0" / "0").unlink()
    with pytest.raises(ViformError, match=r"chunk 2 \(ticks 16–23\) is missing"):
        open_spikes(path)


@pytest.mark.parametrize("offset", [5, 20, -3])
def test_damaged_chunk_names_the_store_and_chunk(tmp_path, offset):
    path, _ = store(tmp_path)
    chunk = path / "c" / "1" / "0" / "0"
    raw = bytearray(chunk.read_bytes())
    raw[offset] ^= 0x01
    chunk.write_bytes(bytes(raw))
    source = open_spikes(path)
    assert np.array_equal(source.read_ticks(0, 8), source.read_ticks(0, 8))  # other chunks still read
    with pytest.raises(ViformError, match=r"s\.zarr.*ticks 8"):
        source.read_ticks(0, 40)


def test_swapped_chunks_are_caught(tmp_path):
    path, _ = store(tmp_path)
    a, b = path / "c" / "0" / "0" / "0", path / "c" / "1" / "0" / "0"
    da, db = a.read_bytes(), b.read_bytes()
    a.write_bytes(db)
    b.write_bytes(da)
    with pytest.raises(ViformError, match="CRC-32"):
        verify_spikes(path)


@pytest.mark.parametrize("field,value,needle", [
    ("clock_hz", -1, "clock_hz"), ("clock_hz", float("inf"), "clock_hz"), ("height", -1, "height"),
    ("threshold_electrons", float("nan"), "threshold_electrons"), ("n_ticks", 10**12, "ticks"),
    ("bit_order", "big", "bit_order"), ("rows", "diagonal", "rows"), ("chunks", [1, 2], "manifest"),
])
def test_forged_attributes_are_refused(tmp_path, field, value, needle):
    path, _ = store(tmp_path)
    edit_header(path, lambda h: h.__setitem__(field, value))
    with pytest.raises(ViformError, match=needle):
        open_spikes(path)


def test_missing_key_and_unsigned_edit(tmp_path):
    path, _ = store(tmp_path)
    edit_header(path, lambda h: h.pop("width"))
    with pytest.raises(ViformError, match="required field 'width' is missing"):
        open_spikes(path)
    path2 = save_spikes(tmp_path / "t.zarr", SpikeStream(np.zeros((4, 2, 8), bool), 1e3))
    edit_header(path2, lambda h: h.__setitem__("clock_hz", 2e3), redigest=False)
    with pytest.raises(ViformError, match="header is damaged or was edited"):
        open_spikes(path2)


def test_bottom_up_rows_are_honoured(tmp_path):
    path, s = store(tmp_path)
    edit_header(path, lambda h: h.__setitem__("rows", "bottom-up"))
    assert np.array_equal(open_spikes(path).read_ticks(0, 40), s.spikes[:, ::-1])
