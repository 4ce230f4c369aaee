"""The catalogue on the command line: viform scenes, help texts, --scene-set, descriptions as SCENE,
and scene-clip datasets whose ground truth a person can see (lux beside a display PNG)."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from viform.cli import main
from viform.light.catalog import SCENES


@pytest.fixture
def run(capsys):
    def go(*args):
        code = main(list(args))
        captured = capsys.readouterr()
        return SimpleNamespace(exit_code=code or 0, output=captured.out, err=captured.err)

    return go


def test_scenes_lists_every_entry_and_shows_descriptions(run):
    out = run("scenes", "--json")
    rows = json.loads(out.output)
    assert [r["name"] for r in rows] == list(SCENES)
    for r in rows:
        assert (r["description"] is None) == bool(r["code"])  # described, or says why it is code
    shown = run("scenes", "show", "multi-object")
    assert shown.exit_code == 0 and "viform_scene: 1" in shown.output
    missing = run("scenes", "show", "night-road-fog")
    assert missing.exit_code == 2 and "range-gated" in missing.err


def test_help_texts_list_every_scene(run):
    for command in ("simulate", "highspeed", "capture", "compare", "sweep"):
        text = " ".join(run(command, "--help").output.split())
        for name in SCENES:
            assert name in text, (command, name)


def test_simulate_a_description_with_settings_and_truth(run, tmp_path):
    doc = {"viform_scene": 1, "name": "box", "canvas": {"width_px": 40, "height_px": 24},
           "parameters": {"v": {"default": 1000.0}},
           "background": {"source": {"solid": {"lux": 3.0}}},
           "layers": [{"source": {"solid": {"lux": 30.0}}, "shape": {"rectangle": {"width_px": 8, "height_px": 6}},
                       "position_px": [10, 12], "object": {"id": 1, "class": "box"},
                       "motion": {"velocity": {"px_per_s": ["$v", 0.0]}}}]}
    scene = tmp_path / "box.yaml"
    scene.write_text(json.dumps(doc))
    out = run("simulate", str(scene), "--duration", "0.002", "--out", str(tmp_path / "s.dat"), "--scene-set",
               "v=2000,brightness=2", "--truth", str(tmp_path / "truth"), "--json")
    assert out.exit_code == 0, out.output
    summary = json.loads(out.output)
    assert (summary["height"], summary["width"]) == (24, 40)
    gt = (tmp_path / "truth" / "mot" / "s" / "gt" / "gt.txt").read_text().splitlines()
    assert gt and gt[0].split(",")[1] == "1"
    bad = run("simulate", str(scene), "--duration", "0.002", "--out", str(tmp_path / "t.dat"), "--scene-set",
               "w=3")
    assert bad.exit_code == 2 and "setting w=3" in bad.err and not (tmp_path / "t.dat").exists()


def test_scene_set_reaches_builtin_parameters(run, tmp_path):
    out = run("simulate", "translating", "--duration", "0.001", "--height", "16", "--width", "24", "--out",
               str(tmp_path / "a.dat"), "--scene-set", "velocity_px_per_s=[100,0],brightness=3", "--json")
    assert out.exit_code == 0, out.output
    meta = json.loads((tmp_path / "a.dat.json").read_text()) if (tmp_path / "a.dat.json").exists() else None
    if meta is not None:
        params = meta["scene"]["builtin"]["parameters"]
        assert params["velocity_px_per_s"] == [100, 0] and params["max_lux"] == 12.0
    bad = run("simulate", "translating", "--duration", "0.001", "--out", str(tmp_path / "b.dat"), "--scene-set",
               "velocity=3")
    assert bad.exit_code == 2 and "velocity=3" in bad.err


def test_dataset_truth_in_lux_beside_a_visible_png(run, tmp_path):
    import imageio.v3 as iio

    out = run("dataset", "--scenes", "multi-object", "--clips", "1", "--duration", "0.004", "--height", "32",
               "--width", "48", "--truth-every-ticks", "40", "--out", str(tmp_path / "d"), "--workers", "1",
               "--no-progress")
    assert out.exit_code == 0, out.output
    assert "spikeone (the dataset default" in out.output
    manifest = json.loads((tmp_path / "d" / "manifest.json").read_text())
    clip = manifest["clips"][0]
    assert "too_dark" in clip and clip["spikes_per_pixel_per_truth_step"] >= 0
    frame = clip["gt_frames"][0]
    lux = np.load(tmp_path / "d" / "gt_lux" / frame["lux_file"])
    png = iio.imread(tmp_path / "d" / "gt" / frame["file"])
    assert lux.dtype == np.float32 and png.max() >= 200  # the display scale is the clip's own
    white = frame["display_white_lux"]
    v = np.clip(lux / white, 0, 1)
    expected = np.rint(255 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055))
    assert np.abs(png.astype(float) - expected).max() <= 1


def test_scenes_json_and_json_file(tmp_path, capsys):
    """`viform scenes` and `scenes show` print JSON and write it with --json-file, as every command does."""
    import json

    from viform.cli import main

    assert main(["scenes", "--json", "--json-file", str(tmp_path / "a" / "s.json")]) == 0
    out = capsys.readouterr().out
    assert json.loads(out) == json.loads((tmp_path / "a" / "s.json").read_text())
    assert any(row["name"] == "multi-object" for row in json.loads(out))
    assert main(["scenes", "show", "multi-object", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["name"] == "multi-object"
    (tmp_path / "d.json").mkdir()
    assert main(["scenes", "--json-file", str(tmp_path / "d.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--json-file" in err
