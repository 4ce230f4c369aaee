"""Scene datasets with exact truth (issue 21 item 2): same bits for any worker count, truth files that
round-trip through the loaders, the clean twin, and the truth matching the scene it was drawn from."""

from __future__ import annotations

import json

import numpy as np
import pytest

from viform.datasets import build_dataset, make_settings
from viform.datasets.build import scene_clips
from viform.datasets.loaders import open_dataset
from viform.datasets.scene_clips import make_scene, scene_parameters
from viform.light.catalog import builtin_scene
from viform.vision.flow import read_flo
from viform.vision.motchallenge import read_gt, read_seqinfo

H, W = 24, 32
STEP = 20  # ticks per truth frame


@pytest.fixture(scope="module")
def scene_settings():
    return make_settings(height=H, width=W, seed=5, truth_every_ticks=STEP)


@pytest.fixture(scope="module")
def scene_set(scene_settings):
    # 4 clips: two scenes, each with its clean twin
    return scene_clips("rotating,multi-object", 1, 0.003, scene_settings, pairs=True)


@pytest.fixture(scope="module")
def scene_reference(tmp_path_factory, scene_set, scene_settings, client1):
    out = tmp_path_factory.mktemp("scenes") / "ds"
    summary = build_dataset(scene_set, out, scene_settings, client=client1, block_ticks=32, progress=False)
    assert summary["converted"] == 4 and not summary["failed"], summary
    return out


def _all_files(root):
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.suffix not in (".json", ".yaml")} | {"manifest": (root / "manifest.json").read_bytes()}


def test_two_workers_write_the_bits_of_one(scene_reference, scene_set, scene_settings, client2, tmp_path):
    out = tmp_path / "ds2"
    summary = build_dataset(scene_set, out, scene_settings, client=client2, block_ticks=50, progress=False)
    assert summary["converted"] == 4
    files = _all_files(out)
    assert files == _all_files(scene_reference)
    assert any(name.startswith("flow/") for name in files) and any(name.startswith("mot/") for name in files)


def test_parameters_are_drawn_per_clip_and_recorded(scene_reference, scene_settings):
    manifest = json.loads((scene_reference / "manifest.json").read_text())
    rows = {r["clip"]: r for r in manifest["clips"]}
    assert set(rows) == {"rotating-0000", "rotating-0000-clean", "multi-object-0000", "multi-object-0000-clean"}
    noisy, clean = rows["rotating-0000"], rows["rotating-0000-clean"]
    assert noisy["scene_parameters"] == clean["scene_parameters"] == scene_parameters(
        "rotating", "rotating-0000", 5, scene_settings.max_lux)
    assert noisy["seed"] == clean["seed"] and clean["clean"] and not noisy["clean"]
    assert noisy["sha256"] != clean["sha256"]  # photon noise is the only difference
    # another dataset seed draws other parameters
    assert scene_parameters("rotating", "rotating-0000", 6, scene_settings.max_lux) != noisy["scene_parameters"]
    assert manifest["clips"][0]["truth"]["step_ticks"] == STEP


def test_clean_twin_is_the_deterministic_model(scene_reference):
    folder = open_dataset(scene_reference, window_ticks=STEP)
    clean = folder.source("rotating-0000-clean")
    noisy = folder.source("rotating-0000")
    # same light: the mean firing rates agree within the photon noise of the noisy clip
    a = clean.read_ticks(0, clean.n_ticks).mean()
    b = noisy.read_ticks(0, noisy.n_ticks).mean()
    n = clean.n_ticks * H * W
    assert abs(a - b) < 5 * np.sqrt(b * (1 - b) / n) + 2 / clean.n_ticks


def test_truth_files_match_the_scene(scene_reference):
    manifest = json.loads((scene_reference / "manifest.json").read_text())
    row = next(r for r in manifest["clips"] if r["clip"] == "multi-object-0000")
    scene = builtin_scene("multi-object", H, W, **row["scene_parameters"])
    clock = manifest["clock_hz"]
    frames = row["gt_frames"]
    assert [f["frame"] for f in frames] == list(range(1, row["ticks"] // STEP + 1))
    for f in frames[:-1]:
        t0, t1 = f["frame"] * STEP / clock, (f["frame"] + 1) * STEP / clock
        assert f["time_s"] == pytest.approx(t0)
        flow, valid = read_flo(scene_reference / "flow" / f["flow"])
        truth = scene.optical_flow_px(t0, t1)
        assert np.array_equal(valid, truth.valid)
        np.testing.assert_allclose(flow[:, valid], truth.flow_px[:, valid], atol=1e-5)  # float32 on disk
    gt = read_gt(scene_reference / row["truth"]["mot"]["gt"])
    info = read_seqinfo(scene_reference / row["truth"]["mot"]["seqinfo"])
    assert info["step_ticks"] == STEP and info["clock_hz"] == clock and info["n_frames"] == len(frames)
    first = [o for o in scene.objects(STEP / clock)]
    rows1 = gt[gt[:, 0] == 1]
    assert sorted(rows1[:, 1].astype(int)) == sorted(o.object_id for o in first)
    for obj in first:
        r = rows1[rows1[:, 1] == obj.object_id][0]
        np.testing.assert_allclose(r[2:6], obj.box_xywh, atol=1e-4)


def test_loader_yields_truth_of_every_kind(scene_reference):
    folder = open_dataset(scene_reference, window_ticks=STEP)
    assert folder.truth_kinds == ("motion", "objects")
    keys = None
    for i in range(len(folder)):
        sample = folder[i]
        keys = keys or set(sample)
        assert set(sample) == keys  # the same keys for every sample, so batches stack
        assert sample["flow"].shape == (2, H, W) and sample["flow_valid"].shape == (H, W)
        assert np.isfinite(sample["flow"]).all()
        assert sample["boxes"].shape == (sample["ids"].size, 4)
    assert {"flow", "flow_valid", "boxes", "ids", "classes", "visibility"} <= keys


def test_night_road_depth_is_written(tmp_path, client1):
    settings = make_settings(height=32, width=48, seed=1, truth_every_ticks=40)
    clips = scene_clips("night-road-fog", 1, 0.002, settings)
    out = tmp_path / "fog"
    build_dataset(clips, out, settings, client=client1, progress=False)
    sample = open_dataset(out, window_ticks=21)[0]
    scene = make_scene(clips[0])
    np.testing.assert_array_equal(sample["depth"], scene.depth_m(0.001).astype(np.float32))
    assert np.isinf(sample["depth"][0]).all() and len(sample["ids"]) == 4


def test_scene_options_are_checked(scene_settings):
    from viform._validate import ViformError

    with pytest.raises(ViformError, match="--scenes 'nonesuch' is not allowed"):
        scene_clips("nonesuch", 1, 0.01, scene_settings)
    with pytest.raises(ViformError, match="--duration 0.0001 s is shorter than one truth step"):
        scene_clips("rotating", 1, 1e-4, scene_settings)
    with pytest.raises(ViformError, match="--clips"):
        scene_clips("rotating", 0, 0.01, scene_settings)
