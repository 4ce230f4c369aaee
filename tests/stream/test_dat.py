"""The spike-camera .dat layout and the shared real files (shared/data/spike/SOURCES.md)."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.imaging import accumulation_8bit, interval_8bit, interval_ticks
from viform.stream.container import SpikeStream
from viform.stream.dat import pack_frames, read_dat, write_dat
from viform.stream.io import open_spikes, save_spikes


def random_stream(t=7, h=4, w=8, seed=0, p=0.3):
    rng = np.random.default_rng(seed)
    return SpikeStream(rng.random((t, h, w)) < p, clock_hz=20_000.0, threshold_electrons=50.0)


def test_bit_order_is_lsb_first_and_rows_bottom_up(tmp_path):
    # one frame 2×8: set pixel (row 0, col 1) of the upright image
    frame = np.zeros((1, 2, 8), bool)
    frame[0, 0, 1] = True
    raw = pack_frames(frame, flip=True)
    # stored bottom-up: upright row 0 is stored second → byte 1; column 1 → bit 1 (LSB first)
    assert raw == bytes([0, 0b10])
    path = tmp_path / "one.dat"
    path.write_bytes(raw)
    assert np.array_equal(read_dat(path, 2, 8).read_ticks(0, 1), frame)
    assert np.array_equal(read_dat(path, 2, 8, flip=False).read_ticks(0, 1), frame[:, ::-1])


def test_round_trip(tmp_path):
    stream = random_stream()
    path = write_dat(tmp_path / "s.dat", stream)
    back = read_dat(path, 4, 8, clock_hz=20_000.0)
    assert back.n_ticks == 7 and np.array_equal(back.read_ticks(0, 7), stream.spikes)


def test_a_dat_that_cannot_fit_on_its_disk_is_refused_and_the_old_file_kept(tmp_path, monkeypatch):
    """The size of a .dat is exact (ticks × bytes per frame): one larger than the free space is refused
    before a byte is written, naming both sizes, and the file already there stays whole."""
    import shutil
    from collections import namedtuple

    path = write_dat(tmp_path / "s.dat", random_stream())
    old = path.read_bytes()
    usage = namedtuple("usage", "total used free")
    stream = random_stream(t=100)  # 100 ticks × 4 bytes = 400 bytes
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(10**6, 10**6 - 399, 399))
    with pytest.raises(ViformError, match=r"not enough disk space: s\.dat needs 400 bytes .*399 bytes free"):
        write_dat(path, stream)
    assert path.read_bytes() == old and sorted(p.name for p in tmp_path.iterdir()) == ["s.dat", "s.dat.json"]
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(10**6, 10**6 - 400, 400))
    write_dat(path, stream)  # exactly enough
    assert read_dat(path, 4, 8).n_ticks == 100


def test_416_column_variant(tmp_path):
    h, w = 250, 400
    frames = np.random.default_rng(1).random((2, h, w)) < 0.2
    padded = np.zeros((2, h, 416), bool)
    padded[:, :, :w] = frames
    padded[:, :, w:] = True  # padding is ignored whatever it holds
    (tmp_path / "old.dat").write_bytes(pack_frames(padded))
    source = read_dat(tmp_path / "old.dat", h, w)
    assert source.stored_width == 416
    assert np.array_equal(source.read_ticks(0, 2), frames)


def test_partial_file_is_refused_or_trimmed_on_request(tmp_path):
    path = tmp_path / "cut.dat"
    path.write_bytes(pack_frames(random_stream().spikes) + b"\x01\x02")
    with pytest.raises(ViformError, match="not a whole number"):
        read_dat(path, 4, 8)
    assert read_dat(path, 4, 8, allow_partial=True).n_ticks == 7


def test_missing_or_wrong_size_is_a_clear_error(tmp_path):
    path = write_dat(tmp_path / "s.dat", random_stream(), sidecar=False)
    with pytest.raises(ViformError, match="height and width are required"):
        read_dat(path, None, None)
    with pytest.raises(ViformError, match="not a whole number"):
        read_dat(path, 5, 8)


def test_zarr_and_npz_round_trips_keep_metadata(tmp_path):
    stream = random_stream(t=50)
    stream.metadata = {"sensor": {"model": "spike", "threshold_electrons": 50.0}}
    for name in ("s.zarr", "s.npz"):
        save_spikes(tmp_path / name, stream, block_ticks=16)
        back = open_spikes(tmp_path / name)
        assert back.clock_hz == 20_000.0 and back.threshold_electrons == 50.0
        assert np.array_equal(back.read_ticks(0, 50), stream.spikes)
        assert np.array_equal(back.read_ticks(13, 29), stream.spikes[13:29])
    assert open_spikes(tmp_path / "s.zarr").metadata["sensor"]["model"] == "spike"


def test_events_view_and_time_slicing():
    stream = random_stream(t=10)
    ev = stream.events()
    assert ev.dtype.names == ("x", "y", "t", "p")
    assert ev.size == stream.spike_count()
    k, y, x = np.nonzero(stream.spikes)
    assert np.array_equal(ev["x"], x) and np.array_equal(ev["y"], y)
    assert np.array_equal(ev["t"], np.rint((k + 1) / 20_000.0 * 1e6).astype(np.int64))
    part = stream.slice_time(2 / 20_000, 5 / 20_000)
    assert part.n_ticks == 3 and np.array_equal(part.spikes, stream.spikes[2:5])
    with pytest.raises(ViformError, match="outside the stream"):
        stream.tick_of(1.0)


def test_reds_sim_reconstructs_to_its_ground_truth(spike_data_dir):
    """Mid-stream images of reds_sim_400x250.dat against the ground-truth PNG (frame 150).

    SOURCES.md gives ≈ 31.6 dB for the 41-frame average ÷ 0.6 and ≈ 21.8 dB for 1/ISI.
    """
    import imageio.v3 as iio
    from skimage.metrics import peak_signal_noise_ratio

    source = open_spikes(spike_data_dir / "reds_sim_400x250.dat", 250, 400)
    assert source.n_ticks == 301
    truth = iio.imread(spike_data_dir / "reds_sim_400x250_gt.png")
    tfp = accumulation_8bit(source, 150, half_window_ticks=20, scale=0.6)
    tau, _ = interval_ticks(source, [150])
    tfi = interval_8bit(tau[0], scale=0.6)
    assert peak_signal_noise_ratio(truth, tfp) > 31.0
    assert peak_signal_noise_ratio(truth, tfi) > 21.0
    # without the bottom-up flip the image is upside down and nothing matches
    flipped = open_spikes(spike_data_dir / "reds_sim_400x250.dat", 250, 400, flip=False)
    assert peak_signal_noise_ratio(truth, accumulation_8bit(flipped, 150, 20, 0.6)) < 20.0


def test_real_uhsr_npz_loads_as_a_stream(spike_data_dir):
    source = open_spikes(spike_data_dir / "real_uhsr_250x250.npz")
    assert source.shape == (200, 250, 250)
    assert 0.0 < source.summary()["mean_firing_rate_per_tick"] < 1.0
    assert "label_name" in source.metadata
