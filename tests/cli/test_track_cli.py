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
