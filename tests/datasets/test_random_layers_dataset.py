"""`dataset --scenes random-layers`: drawn described scenes with truth, the same bits for 1 and 2 workers,
drawn parameters and descriptions in the manifest; `--scene-set` and `--images` on `dataset`."""

from __future__ import annotations

import json

import numpy as np
import pytest

from viform.cli import main
from viform.datasets import build_dataset, make_settings
from viform.datasets.build import scene_clips
from viform.datasets.scene_clips import random_layers_clip, random_layers_ranges, scene_parameters
from viform.light.catalog import load_scene
from viform.vision.flow import read_flo

H, W = 32, 48
STEP = 20  # ticks per truth frame; 0.001 s = 40 ticks = 2 truth frames


@pytest.fixture(scope="module")
def rl_settings():
    return make_settings(height=H, width=W, seed=3, truth_every_ticks=STEP)


@pytest.fixture(scope="module")
def rl_clips(rl_settings):
    return scene_clips("random-layers", 2, 0.001, rl_settings, scene_settings={"n_objects": [1, 2]})


@pytest.fixture(scope="module")
def rl_reference(tmp_path_factory, rl_clips, rl_settings, client1):
    out = tmp_path_factory.mktemp("rl") / "ds"
    summary = build_dataset(rl_clips, out, rl_settings, client=client1, block_ticks=16, progress=False)
    assert summary["converted"] == 2 and not summary["failed"], summary
    return out


def _all_files(root):
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.suffix != ".json" and p.name != "config.yaml"} | \
        {"manifest": (root / "manifest.json").read_bytes()}


def test_two_workers_write_the_bits_of_one(rl_reference, rl_clips, rl_settings, client2, tmp_path):
    out = tmp_path / "ds2"
    summary = build_dataset(rl_clips, out, rl_settings, client=client2, block_ticks=25, progress=False)
    assert summary["converted"] == 2
    files = _all_files(out)
    assert files == _all_files(rl_reference)
    for folder in ("flow/", "depth/", "mot/", "scenes/", "spike/"):
        assert any(name.startswith(folder) for name in files), folder


def test_manifest_holds_the_drawn_parameters_and_the_description(rl_reference, rl_settings):
    manifest = json.loads((rl_reference / "manifest.json").read_text())
    rows = {r["clip"]: r for r in manifest["clips"]}
    assert set(rows) == {"random-layers-0000", "random-layers-0001"}
    ranges = random_layers_ranges({"n_objects": [1, 2]}, rl_settings.max_lux)
    for name, row in rows.items():
        description, drawn = random_layers_clip(name, 3, H, W, 0.001, ranges)
        assert row["scene"] == "random-layers" and row["scene_settings"] == {"n_objects": [1, 2]}
        assert row["scene_parameters"] == drawn and row["scene_description"] == description
        assert drawn["ranges"]["peak_lux"] == pytest.approx(rl_settings.max_lux)  # the sensor's full scale
        assert 1 <= len(drawn["objects"]) <= 2
        assert set(row["truth"]["kinds"]) == {"motion", "depth", "objects"}
    assert rows["random-layers-0000"]["scene_parameters"] != rows["random-layers-0001"]["scene_parameters"]


def test_the_written_description_remakes_the_clip(rl_reference):
    manifest = json.loads((rl_reference / "manifest.json").read_text())
    row = manifest["clips"][0]
    scene = load_scene(str(rl_reference / row["description_file"]["file"]))  # what `viform simulate` loads
    frame = row["gt_frames"][0]
    stored = np.load(rl_reference / "gt_lux" / frame["lux_file"])
    np.testing.assert_array_equal(stored, scene.illuminance_lux(frame["time_s"]).astype(np.float32))
    flow, valid = read_flo(rl_reference / "flow" / frame["flow"])
    truth = scene.optical_flow_px(frame["time_s"], row["gt_frames"][1]["time_s"])
    assert np.array_equal(valid, truth.valid) and valid.any()
    np.testing.assert_allclose(flow[:, valid], truth.flow_px[:, valid], atol=1e-4)


def test_scene_set_reaches_a_builtin_scenes_parameters(rl_settings):
    drawn = scene_parameters("translating", "translating-0000", 3, rl_settings.max_lux)
    fixed = scene_parameters("translating", "translating-0000", 3, rl_settings.max_lux,
                             {"period_px": 20, "brightness": 2})
    assert fixed["period_px"] == 20 and drawn["period_px"] != 20
    assert fixed["max_lux"] == pytest.approx(2 * drawn["max_lux"])  # a factor on the drawn level
    assert fixed["velocity_px_per_s"] == drawn["velocity_px_per_s"]


def test_cli_scene_set_on_a_builtin_scene(tmp_path, capsys):
    out = tmp_path / "ds"
    rc = main(["dataset", "--scenes", "translating", "--clips", "1", "--duration", "0.001", "--height", "16",
               "--width", "24", "--truth-every-ticks", "20", "--scene-set", "period_px=20,speed=0",
               "--out", str(out), "--workers", "1", "--no-progress", "--json"])
    assert rc == 0, capsys.readouterr().err
    row = json.loads((out / "manifest.json").read_text())["clips"][0]
    assert row["scene_parameters"]["period_px"] == 20 and row["scene_parameters"]["velocity_px_per_s"] == [0, 0]
    flow, valid = read_flo(out / "flow" / row["gt_frames"][0]["flow"])
    assert valid.all() and not flow.any()  # speed 0: nothing moves


@pytest.mark.parametrize("extra, flag", [
    (["--scenes", "random-layers", "--images", "MISSING"], "--images"),
    (["--scenes", "random-layers", "--images", "EMPTY"], "--images"),
    (["--scenes", "translating", "--images", "EMPTY"], "--images"),
    (["--scenes", "random-layers", "--images", "BROKEN"], "--images"),
    (["--scenes", "random-layers", "--scene-set", "speed_px_per_s=[500,100]"], "--scene-set"),
    (["--scenes", "random-layers", "--scene-set", "n_objects=[0,1000]"], "--scene-set"),
    (["--scenes", "random-layers", "--scene-set", "brightness=-1"], "--scene-set"),
    (["--scenes", "translating", "--scene-set", "nonesuch=1"], "--scene-set"),
])
def test_bad_input_exits_2_naming_the_flag_before_any_work(extra, flag, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "a.png").write_bytes(b"not a png")
    names = {"MISSING": "absent", "EMPTY": "empty", "BROKEN": "broken"}
    extra = [str(tmp_path / names[a]) if a in names else a for a in extra]
    out = tmp_path / "ds"
    rc = main(["dataset", *extra, "--clips", "1", "--duration", "0.001", "--out", str(out), "--height", "16",
               "--width", "24", "--no-progress", "--workers", "1"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and flag in err, err
    assert not out.exists()


def test_src_datasets_refuse_scene_flags(source_clips, tmp_path, capsys):
    for extra, flag in ((["--scene-set", "brightness=2"], "--scene-set"), (["--images", str(tmp_path)], "--images")):
        rc = main(["dataset", str(source_clips), *extra, "--out", str(tmp_path / "ds"), "--frame-rate-hz", "1000",
                   "--no-progress"])
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and flag in err, err
