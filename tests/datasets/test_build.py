"""viform.datasets.build: same bits whatever the workers, resumable, failures isolated (issue 14 items 1, 3)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from viform.datasets import build_dataset, clip_seed, read_config
from viform.datasets.layout import sha256_file

H, W, TICKS = 24, 32, 240  # 6 frames at 1 kHz, 40 kHz clock


def test_two_workers_give_the_bits_of_one(reference, source_clips, settings, client2, tmp_path, dataset_files):
    out = tmp_path / "ds2"
    summary = build_dataset(source_clips, out, settings, client=client2, block_ticks=64, progress=False)
    assert summary["workers"] == 2 and summary["converted"] == 4 and not summary["failed"]
    assert dataset_files(out) == dataset_files(reference)


def test_layout_config_manifest_and_sidecar(reference, settings):
    config = read_config(reference)
    assert (config["spike_h"], config["spike_w"]) == (H, W)
    manifest = json.loads((reference / "manifest.json").read_text())
    assert [c["clip"] for c in manifest["clips"]] == ["clip0", "clip1", "clip2", "video3"]
    for row in manifest["clips"]:
        dat = reference / "spike" / f"{row['clip']}.dat"
        assert row["ticks"] == TICKS and dat.stat().st_size == TICKS * H * W // 8
        assert row["sha256"] == sha256_file(dat)
        assert row["seed"] == clip_seed(7, row["clip"])
        # frames 0, 2, 4 (--gt-every 2) at ticks k / 1 kHz · 40 kHz
        assert [(g["frame"], g["tick"]) for g in row["gt_frames"]] == [(0, 0), (2, 80), (4, 160)]
        assert all((reference / "gt" / g["file"]).is_file() for g in row["gt_frames"])
        side = json.loads((reference / "spike" / f"{row['clip']}.dat.json").read_text())
        for key in ("viform_version", "command_line", "utc_date", "source_clip"):
            assert side[key], key
        assert side["seed"] == row["seed"] and side["height"] == H and side["width"] == W
        sensor = side["metadata"]["sensor"]
        assert sensor["threshold_electrons"] == settings.parameters.threshold_electrons
        assert sensor["clock_hz"] == 40_000.0 and "optics" in sensor
    # different names, different seeds: clips that share no noise
    assert len({row["seed"] for row in manifest["clips"]}) == 4


def test_spike_counts_follow_the_light(reference, settings):
    """Spike count ≈ Σ rate·gt over pixels and ticks: each pixel fires (λΔt)/Q per tick (seed 000 §3.2).

    With the preset's Q (≥ 10⁴ e⁻) the count of a pixel over 240 ticks is set by the light to within one spike
    (photon noise adds √(N/Q)·… ≪ 1 spike), so the total over 768 pixels is within
    768 spikes (quantisation) + 3 % (the preset's PRNU, mean 1, does not bias the sum by
    more than its std/√768) of the expectation from the source frames.
    """
    from viform.datasets.loaders import read_gt

    manifest = json.loads((reference / "manifest.json").read_text())
    row = manifest["clips"][0]
    assert row["spikes"] > 0
    gt0 = read_gt(reference / "gt" / row["gt_frames"][0]["file"])
    # the clip is a texture sliding sideways: its mean light is that of any frame
    expected = row["rate"] * float(gt0.mean()) * TICKS * H * W
    assert abs(row["spikes"] - expected) < H * W + 0.03 * expected, (row["spikes"], expected)


def test_killed_worker_mid_clip_is_redone_with_the_same_bits(reference, source_clips, settings, client2,
                                                             tmp_path, dataset_files):
    out = tmp_path / "crash"
    # the worker converting clip1 exits abruptly after writing 2 of its 4 blocks
    summary = build_dataset(source_clips, out, settings, client=client2, block_ticks=64, progress=False,
                            crash=("clip1", 2))
    assert (out / ".crash-clip1").exists(), "the worker was not killed"
    assert not summary["failed"] and summary["converted"] == 4
    assert not list((out / "spike").glob(".clip1*")), "stale partial file left"
    assert dataset_files(out) == dataset_files(reference)


def test_run_killed_mid_clip_then_rerun_gives_the_same_bits(reference, source_clips, client1, tmp_path,
                                                            dataset_files):
    """The whole converting process dies (SIGKILL-like exit) half-way through clip1's .dat."""
    import subprocess
    import sys

    out = tmp_path / "killed"
    code = ("from viform.datasets import make_settings; from viform.datasets.build import convert_serially; "
            f"s = make_settings(height={H}, width={W}, frame_rate_hz=1000.0, gt_every=2, seed=7); "
            f"convert_serially({str(source_clips)!r}, {str(out)!r}, s, block_ticks=64, crash=('clip1', 2))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 70, proc.stderr
    assert (out / "spike" / "clip0.dat").is_file() and not (out / "spike" / "clip1.dat").exists()
    assert list((out / "spike").glob(".clip1.dat*")), "the kill should leave clip1's partial temporary file"
    from viform.datasets import build_dataset, make_settings

    again = make_settings(height=H, width=W, frame_rate_hz=1000.0, gt_every=2, seed=7)
    summary = build_dataset(source_clips, out, again, client=client1, block_ticks=64, progress=False)
    assert summary["skipped"] == 1 and summary["converted"] == 3, summary
    assert dataset_files(out) == dataset_files(reference)


def test_interrupted_run_resumes_to_the_same_bits(reference, source_clips, settings, client1, tmp_path,
                                                  dataset_files):
    out = tmp_path / "resume"
    shutil.copytree(reference, out)
    (out / "spike" / "clip0.dat.json").unlink()                     # killed before its sidecar
    with open(out / "spike" / "clip1.dat", "r+b") as f:            # damaged data, same size
        f.seek(100)
        f.write(b"\xff" * 8)
    (out / "spike" / ".video3.dat.tmp123.dat").write_bytes(b"partial")  # a killed attempt's temp file
    (out / "gt" / "clip2_000002.png").unlink()                        # missing ground truth
    summary = build_dataset(source_clips, out, settings, client=client1, block_ticks=64, progress=False)
    assert summary["converted"] == 3 and summary["skipped"] == 1, summary  # video3 intact: skipped
    assert not (out / "spike" / ".video3.dat.tmp123.dat").exists()
    assert dataset_files(out) == dataset_files(reference)


def test_block_size_does_not_change_the_bits(reference, source_clips, settings, client1, tmp_path,
                                             dataset_files):
    out = tmp_path / "blocks"
    build_dataset(source_clips, out, settings, client=client1, block_ticks=7, progress=False)
    assert dataset_files(out) == dataset_files(reference)


def test_a_failing_clip_is_reported_and_the_others_are_written(source_with_broken_clip, settings, client1,
                                                               tmp_path):
    src = source_with_broken_clip
    summary = build_dataset(src, tmp_path / "ds", settings, client=client1, block_ticks=64, progress=False)
    assert [f["clip"] for f in summary["failed"]] == ["broken"]
    assert "broken" in summary["failed"][0]["error"]
    assert summary["converted"] == 4
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert [f["clip"] for f in manifest["failed"]] == ["broken"]


def test_other_settings_in_an_existing_folder_are_refused(reference, source_clips, tmp_path):
    from viform._validate import ViformError
    from viform.datasets import make_settings

    other = make_settings(height=H, width=W, frame_rate_hz=500.0, gt_every=2, seed=7)
    with pytest.raises(ViformError, match="frame_rate_hz"):
        build_dataset(source_clips, reference, other, workers=1, progress=False)


def test_loader_reads_the_built_dataset(reference):
    """Samples are the 41 ticks around each gt frame that fits; mean(spike)/rate estimates gt.

    Tolerance: over a 41-tick window a pixel's count is known to ±1 spike (Q ≥ 10⁴ e⁻: photon
    noise is ≤ 1 % of an interval), so the image mean is within 1/(41·rate) ≈ 0.04 /√768 per
    pixel on average plus the 3 % PRNU of the preset: 0.03 of full scale.
    """
    from viform.datasets.loaders import open_dataset

    ds = open_dataset(reference, window_ticks=41)
    assert ds.layout == "viform"
    assert len(ds) == 8  # frames 2 and 4 of each clip (frame 0's window starts before tick 0)
    sample = ds[0]
    assert sample["spike"].shape == (41, H, W) and sample["gt_img"].shape == (1, H, W)
    assert sample["start_tick"] == sample["tick"] - 20
    est = sample["spike"].mean(axis=0) / sample["rate"]
    assert abs(float(est.mean()) - float(sample["gt_img"].mean())) < 0.03
    events, size = ds.events(0)
    assert size == (W, H, 1) and events.size == int(sample["spike"].sum())
    assert np.all(np.diff(events["t"]) >= 0) and set(np.unique(events["p"])) <= {0}


def test_own_local_cluster_asks_for_a_clips_modules(source_clips, settings, tmp_path, monkeypatch):
    """``build_dataset`` opens its own LocalCluster with a clip's modules to preload in its fork server
    (``tests/test_parallel.py`` checks that a worker then finds them imported); nothing is written first."""
    from viform._validate import ViformError
    from viform.datasets import build

    asked = {}

    def stop(*args, **kwargs):
        asked.update(kwargs)
        raise ViformError("stopped before the cluster")

    monkeypatch.setattr(build, "open_client", stop)
    with pytest.raises(ViformError, match="stopped"):
        build_dataset(source_clips, tmp_path / "out", settings, workers=1)
    assert asked["preload"] == build.WORKER_MODULES
    assert not (tmp_path / "out").exists()
