"""viform track: MOTChallenge results counted like the truth, scores where the file has truth, bad input."""

import json

import numpy as np
import pytest

from viform.cli import main
from viform.light.catalog import builtin_scene
from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor
from viform.stream.io import save_spikes
from viform.vision import motchallenge as mot

pytest.importorskip("trackeval")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("track")
    sensor = SpikeSensor(threshold_electrons=100)
    scene = builtin_scene("multi-object", height=32, width=48)
    with_truth = save_spikes(folder / "objects.dat", sensor.capture(scene, 0.005, seed=1))
    plain = save_spikes(folder / "still.dat", sensor.capture(StillScene(np.full((8, 8), 3.0)), 0.002, seed=1))
    return with_truth, plain


def test_results_seqinfo_truth_and_scores(files, tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["track", str(files[0]), "--every", "20", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 10 and summary["truth"].startswith("built-in scene 'multi-object'")
    info = mot.read_seqinfo(out / "seqinfo.ini")
    assert info["step_ticks"] == 20 and info["frame_rate_hz"] == 2000.0 and info["n_frames"] == 10
    gt = mot.read_gt(out / "gt.txt")
    assert set(gt[:, 0].astype(int)) == set(range(1, 11))  # frame k = output step k, from 1
    res = mot.read_results(out / "results.txt")
    assert res.size == 0 or res[:, 0].max() <= 10
    assert 0.0 <= summary["scores"]["hota"] <= 1.0 and (out / "overlay.png").stat().st_size > 0
    # the same truth given as a file gives the same scores
    assert main(["track", str(files[0]), "--every", "20", "--truth", str(out / "gt.txt"), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["scores"]["hota"] == pytest.approx(summary["scores"]["hota"], abs=1e-3)


@pytest.mark.parametrize("args, message", [
    (["--every", "0"], "--every = 0 is not allowed"),
    (["--every", "-3"], "--every"),
    (["--every", "1000"], "--every = 1000 is longer than the stream"),
    (["--scores"], "--scores: "),
])
def test_bad_input_one_line_exit_2_nothing_written(files, tmp_path, capsys, args, message):
    out = tmp_path / "never"
    rc = main(["track", str(files[1]), "--out", str(out), *args])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_empty_stream_and_fractional_step(tmp_path, files, capsys):
    empty = tmp_path / "empty.dat"
    empty.write_bytes(b"")
    assert main(["track", str(empty), "--height", "4", "--width", "8", "--out", str(tmp_path / "o")]) == 2
    assert main(["track", str(files[0]), "--every", "2.5", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "no whole frame" in err[0] and "--every" in err[1]
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def clip_with_truth(tmp_path_factory):
    """A multi-object clip simulated with its truth written every 40 ticks (simulate --truth)."""
    folder = tmp_path_factory.mktemp("aligned")
    dat = folder / "mo.dat"
    assert main(["simulate", "multi-object", "--duration", "0.005", "--height", "32", "--width", "48",
                 "--threshold-electrons", "100", "--out", str(dat), "--truth", str(folder / "truth")]) == 0
    return dat, folder / "truth" / "mot" / "mo" / "gt" / "gt.txt"


def test_truth_with_another_step_is_scored_at_its_own_instants(clip_with_truth, tmp_path, capsys):
    # the truth has 40 ticks a frame (its seqinfo.ini says so); results every 10 ticks are scored at the
    # truth's instants (every 4th result frame), never frame k against frame k
    dat, gt = clip_with_truth
    capsys.readouterr()
    assert main(["track", str(dat), "--every", "10", "--truth", str(gt), "--json"]) == 0
    aligned = json.loads(capsys.readouterr().out)
    assert any("every 40 ticks" in n for n in aligned["notes"])
    assert aligned["scores"]["n_frames"] == 5
    # the same as tracking every 10 and keeping every 4th frame by hand
    assert main(["track", str(dat), "--every", "10", "--out", str(tmp_path / "t"), "--json"]) == 0
    capsys.readouterr()
    res = mot.read_results(tmp_path / "t" / "results.txt")
    res = res[res[:, 0] % 4 == 0]
    res[:, 0] //= 4
    from viform.vision.metrics import score_tracking
    expected = score_tracking(mot.read_gt(gt), res, mot.step_times_s(5, 40, 40_000.0), 40_000.0)
    assert aligned["scores"]["hota"] == pytest.approx(expected["hota"], abs=1e-9)
    # a step that does not divide the truth's is refused
    assert main(["track", str(dat), "--every", "15", "--truth", str(gt), "--out", str(tmp_path / "n")]) == 2
    err = capsys.readouterr().err
    assert "records 40 ticks a frame" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "n").exists()


def test_one_truth_wherever_written(clip_with_truth, tmp_path, capsys):
    # simulate --truth and track write the same gt.txt: boxes clipped to the image, the visible
    # fraction and the detectability (charge against Q) in the last columns
    dat, gt = clip_with_truth
    assert main(["track", str(dat), "--every", "40", "--out", str(tmp_path / "t")]) == 0
    capsys.readouterr()
    assert (tmp_path / "t" / "gt.txt").read_text() == gt.read_text()
    rows = mot.read_gt(gt)
    assert rows[:, 2:4].min() >= 0 and (rows[:, 2] + rows[:, 4]).max() <= 48
    assert (rows[:, 9] >= 0).all()  # the sensor is known: every row has its detectability


def test_no_object_in_view_is_said_or_refused(tmp_path, capsys):
    dat = tmp_path / "tr.dat"
    assert main(["simulate", "translating", "--duration", "0.002", "--height", "16", "--width", "24",
                 "--out", str(dat)]) == 0
    capsys.readouterr()
    assert main(["track", str(dat), "--every", "20", "--scores", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "no object in view" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
    assert main(["track", str(dat), "--every", "20", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "not scored" in out and "HOTA" not in out
    assert not (tmp_path / "o" / "gt.txt").exists() and not (tmp_path / "o" / "scores.json").exists()


def test_speed_is_the_scenes(tmp_path, capsys):
    # the bullet (10,000 px/s at 400 × 250) enters and leaves: its clipped box's centre is slower
    scene = builtin_scene("multi-object", height=50, width=80)
    dat = save_spikes(tmp_path / "b.dat", SpikeSensor(threshold_electrons=100).capture(scene, 0.012, seed=1))
    assert main(["track", str(dat), "--every", "40", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)["scores"]
    for oid in (3, 4):  # bullet, car: 10,000 and 4,000 px/s at 400 px, × 80/400 here
        vx, vy = scene.velocity_px_per_s(scene.specs[oid - 1], 0.005)
        assert s["objects"][str(oid)]["speed_px_per_s"] == pytest.approx(np.hypot(vx, vy), rel=1e-6)
