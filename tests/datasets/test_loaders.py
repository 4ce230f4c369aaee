"""viform.datasets.loaders on the shared real files: Spike-Zoo layout, .npz 'spk', tonic events (issue 14 item 2)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from viform._validate import ViformError
from viform.datasets.loaders import open_dataset, spikes_to_tonic

SHARED = Path(os.environ.get("VIFORM_SPIKE_DATA")
              or Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "spike")
pytestmark = pytest.mark.skipif(not (SHARED / "reds_sim_400x250.dat").is_file(),
                                reason=f"shared spike data absent: {SHARED / 'reds_sim_400x250.dat'}")


def test_spike_zoo_layout_sample_reconstructs_its_ground_truth(spike_zoo_layout):
    """41 ticks around the middle tick / 0.6 give 31.6 dB PSNR against the gt (SOURCES.md's figure).

    A flipped or misaligned window gives far less (< 15 dB), so 30 dB checks rows, bit order
    and the centring of the window on the ground-truth instant.
    """
    ds = open_dataset(spike_zoo_layout)
    assert ds.layout == "spike-zoo" and len(ds) == 2
    sample = ds[ds.clips.index(next(c for c in ds.clips if c.name == "reds_sim"))]
    assert sample["spike"].shape == (41, 250, 400) and sample["gt_img"].shape == (1, 250, 400)
    assert sample["tick"] == 150 and sample["start_tick"] == 130 and sample["rate"] == 0.6
    estimate = np.clip(sample["spike"].mean(axis=0) / sample["rate"], 0, 1)
    psnr = 10 * np.log10(1 / np.mean((estimate - sample["gt_img"][0]) ** 2))
    assert psnr > 30.0, psnr


def test_shared_folder_as_is_reads_dat_and_npz(tmp_path):
    """The shared folder itself: .dat with `<stem>_gt.png` beside it; the real .npz under key 'spk'."""
    ds = open_dataset(SHARED, height=250, width=400)
    names = {c.name: c for c in ds.clips}
    assert set(names) == {"reds_sim_400x250", "reds_sim2_400x250", "real_uhsr_250x250"}
    assert names["reds_sim_400x250"].n_ticks == 301 and len(names["reds_sim_400x250"].gt) == 1
    uhsr = ds.source("real_uhsr_250x250")
    assert uhsr.shape == (200, 250, 250)
    assert len(ds) == 2  # the recognition clip has no ground-truth image
    with pytest.raises(ViformError, match="not in"):
        ds.source("no-such-clip")


def test_tonic_events_match_the_bits():
    from viform.stream.io import open_spikes

    source = open_spikes(SHARED / "reds_sim_400x250.dat", 250, 400)
    events, sensor_size = spikes_to_tonic(source, 100, 110)
    block = source.read_ticks(100, 110)
    assert sensor_size == (400, 250, 1)
    assert events.size == int(block.sum())
    assert set(events.dtype.names) == {"x", "y", "t", "p"} and not events["p"].any()
    # t: end of the tick in µs (25 µs ticks at 40 kHz); (x, y) are (column, row from the top)
    ticks = np.rint(events["t"] / 25.0).astype(int) - 1
    assert ticks.min() >= 100 and ticks.max() <= 109 and np.all(np.diff(events["t"]) >= 0)
    assert np.all(block[ticks - 100, events["y"], events["x"]])


def test_missing_size_is_refused_naming_what_to_give(tmp_path):
    (tmp_path / "a.dat").symlink_to((SHARED / "reds_sim_400x250.dat").resolve())
    with pytest.raises(ViformError, match="height"):
        open_dataset(tmp_path)


def test_config_yaml_without_size_is_refused(tmp_path):
    (tmp_path / "config.yaml").write_text("spike_h: 250\n")
    (tmp_path / "a.dat").symlink_to((SHARED / "reds_sim_400x250.dat").resolve())
    with pytest.raises(ViformError, match="spike_w"):
        open_dataset(tmp_path)


def test_viform_npz_and_spike_zoo_npz_side_by_side(tmp_path):
    """A .npz written by viform (key 'spikes' + header) and Spike-Zoo's ('spk') open the same way."""
    from viform.stream.container import SpikeStream
    from viform.stream.io import save_spikes

    bits = np.random.default_rng(3).random((50, 8, 16)) < 0.2
    save_spikes(tmp_path / "ours.npz", SpikeStream(bits, 40_000.0, 100.0))
    (tmp_path / "theirs.npz").symlink_to((SHARED / "real_uhsr_250x250.npz").resolve())
    ds = open_dataset(tmp_path)
    assert np.array_equal(ds.source("ours").read_ticks(0, 50), bits)
    assert ds.source("theirs").shape == (200, 250, 250)
