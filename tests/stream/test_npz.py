"""The .npz layout: Spike-Zoo's `spk` key, declared axis order, streamed and checked reads."""

import io
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from viform._validate import ViformError
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes, verify_spikes
from viform.stream.npz import read_npz

SHARED = Path(os.environ.get("VIFORM_SPIKE_DATA")
              or Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "spike")


def stream(t=30, h=5, w=7, seed=1):
    return SpikeStream(np.random.default_rng(seed).random((t, h, w)) < 0.3, 20_000.0, 40.0)


def test_written_file_is_spike_zoo_readable(tmp_path):
    s = stream()
    path = save_spikes(tmp_path / "s.npz", s, block_ticks=4)
    with np.load(path) as data:  # what a Spike-Zoo loader does
        assert data["spk"].dtype == np.uint8 and data["spk"].shape == (30, 5, 7)
        assert np.array_equal(data["spk"].astype(bool), s.spikes)
    back = open_spikes(path)
    assert back.clock_hz == 20_000.0 and back.threshold_electrons == 40.0
    assert np.array_equal(back.read_ticks(7, 23), s.spikes[7:23])  # random access after a later read
    assert np.array_equal(back.read_ticks(0, 30), s.spikes)
    assert verify_spikes(path)["verified"]


def test_older_spikes_key_and_other_keys(tmp_path):
    s = stream()
    np.savez(tmp_path / "old.npz", spikes=s.spikes.astype(np.uint8), clock_hz=30_000.0, label=3)
    old = open_spikes(tmp_path / "old.npz")
    assert old.clock_hz == 30_000.0 and old.metadata["label"] == 3
    assert np.array_equal(old.read_ticks(0, 30), s.spikes)
    hwt = np.transpose(s.spikes, (1, 2, 0))
    np.savez(tmp_path / "hwt.npz", frames=hwt)
    with pytest.raises(ViformError, match="axis order of array 'frames'.*not"):
        read_npz(tmp_path / "hwt.npz", key="frames")  # never guessed
    back = read_npz(tmp_path / "hwt.npz", key="frames", axes="hwt")
    assert back.shape == (30, 5, 7) and np.array_equal(back.read_ticks(0, 30), s.spikes)
    with pytest.raises(ViformError, match="axes = 'tx'"):
        read_npz(tmp_path / "hwt.npz", key="frames", axes="tx")
    with pytest.raises(ViformError, match="contradicts"):
        read_npz(save_spikes(tmp_path / "v.npz", s), axes="hwt")


def test_real_spike_zoo_file():
    path = SHARED / "real_uhsr_250x250.npz"
    if not path.exists():
        pytest.skip(f"shared spike data absent: {path}")
    source = open_spikes(path)
    assert source.shape == (200, 250, 250) and source.metadata["label_name"]
    with np.load(path) as data:
        assert np.array_equal(source.read_ticks(50, 60), data["spk"][50:60].astype(bool))


def test_forged_and_damaged_archives_are_refused(tmp_path):
    # a shape that disagrees with the member's size (a tiny zip declaring 2 GB)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "|u1", "fortran_order": False, "shape": (2000, 1000, 1000)})
    with zipfile.ZipFile(tmp_path / "forged.npz", "w") as zf:
        zf.writestr("spk.npy", buf.getvalue() + bytes(1000))
    with pytest.raises(ViformError, match="declares shape"):
        open_spikes(tmp_path / "forged.npz")
    np.savez(tmp_path / "big.npz", spk=np.full((3, 2, 8), 7, np.uint8))
    with pytest.raises(ViformError, match="other than 0 and 1"):
        open_spikes(tmp_path / "big.npz").read_ticks(0, 3)
    path = save_spikes(tmp_path / "s.npz", stream(t=200, h=16, w=16))
    raw = bytearray(path.read_bytes())
    start = raw.find(b"spk.npy") + 200  # inside the compressed spikes
    raw[start] ^= 0x10
    path.write_bytes(bytes(raw))
    with pytest.raises(ViformError, match="s.npz"):
        verify_spikes(path)
