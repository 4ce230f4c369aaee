"""Whole-stream imaging: the streamed images equal the per-instant ones, for every method."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.imaging import accumulation_image, interval_ticks, reconstruct_ticks
from viform.imaging.multi_interval import multi_interval_image
from viform.imaging.sequence import NpzFrameWriter
from viform.stream.container import SpikeStream


@pytest.fixture
def stream():
    rng = np.random.default_rng(7)
    return SpikeStream(rng.random((400, 6, 7)) < rng.uniform(0.01, 0.5, (6, 7)), 40_000.0, threshold_electrons=100.0)


@pytest.mark.parametrize("align", ["centre", "end", "start"])
def test_accumulation_stream_equals_single_instants(stream, align):
    ticks = [0, 3, 150, 151, 399]
    got = dict(reconstruct_ticks(stream, "accumulation", ticks, window_ticks=41, align=align))
    assert sorted(got) == ticks
    for k in ticks:
        expected = accumulation_image(stream, (k + 0.5) / 40_000, 41 / 40_000, align=align)
        assert np.allclose(got[k].spikes_per_s, expected.spikes_per_s)


def test_interval_and_multi_interval_streams_equal_single_instants(stream):
    every = list(range(0, 400, 3))  # dense: the streamed path
    got = dict(reconstruct_ticks(stream, "interval", every))
    tau, censored = interval_ticks(stream, every)
    assert censored.any()  # near the ends: the streamed path must flag them too
    for i, k in enumerate(every):
        assert np.allclose(got[k].spikes_per_s, 40_000.0 / tau[i])
        assert np.array_equal(got[k].censored, censored[i])
    got = dict(reconstruct_ticks(stream, "multi-interval", [10, 200], spikes_per_side=2, adaptive=False))
    expected = multi_interval_image(stream, 200.5 / 40_000, 2)
    assert np.allclose(got[200].spikes_per_s, expected.spikes_per_s)


def test_bad_method_and_ticks_are_refused(stream):
    with pytest.raises(ViformError, match="method"):
        list(reconstruct_ticks(stream, "tfp", [1]))
    with pytest.raises(ViformError, match="outside"):
        list(reconstruct_ticks(stream, "interval", [400]))


def test_npz_written_frame_by_frame_reads_back(tmp_path):
    path = tmp_path / "light.npz"
    writer = NpzFrameWriter(path, 3, (2, 4), {"lux": np.float32, "censored": np.bool_})
    writer.add_array("ticks", np.array([1, 2, 3]))
    for i in range(3):
        writer.append("lux", np.full((2, 4), i, np.float32))
        writer.append("censored", np.eye(2, 4, dtype=bool))
    writer.close()
    data = np.load(path)
    assert data["lux"].shape == (3, 2, 4) and data["lux"][2, 1, 3] == 2
    assert data["ticks"].tolist() == [1, 2, 3] and data["censored"][1].sum() == 2
