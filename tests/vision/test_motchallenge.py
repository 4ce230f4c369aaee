"""MOTChallenge files: round trips, 1-based boxes on disk, frames = output steps."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.catalog import builtin_scene
from viform.light.scenes import StillScene
from viform.light.truth import TruthUnavailable
from viform.vision import motchallenge as mot


def test_gt_round_trip_counts_pixels_from_one(tmp_path):
    scene = builtin_scene("multi-object", height=64, width=96)
    times = mot.step_times_s(5, 40, 40_000.0)
    np.testing.assert_allclose(times, [0.001, 0.002, 0.003, 0.004, 0.005])
    rows = mot.gt_rows(scene, times)
    assert set(rows[:, 0]) == {1, 2, 3, 4, 5}
    first = {o.object_id: o for o in scene.objects(0.001)}
    r = rows[(rows[:, 0] == 1) & (rows[:, 1] == 1)][0]
    assert tuple(r[2:6]) == pytest.approx(first[1].box_xywh)
    path = mot.write_gt(tmp_path / "gt.txt", rows)
    line = path.read_text().splitlines()[0].split(",")
    assert float(line[2]) == pytest.approx(first[1].x_px + 1, abs=1e-4) and len(line) == 9
    back = mot.read_gt(path)
    np.testing.assert_allclose(back, rows, atol=1e-4)
    assert not list(tmp_path.glob(".*"))  # no temporary left


def test_clipping_and_ignore_flag():
    scene = builtin_scene("multi-object", height=64, width=96)
    rows = mot.gt_rows(scene, [scene.t_ref_s, 0.040], clip_to_field=True)
    assert np.all(rows[:, 2] >= 0) and np.all(rows[:, 2] + rows[:, 4] <= 96 + 1e-9)
    ball = rows[(rows[:, 0] == 1) & (rows[:, 1] == 2)][0]
    assert ball[6] == 0 and ball[8] == 0  # fully hidden: MOT's ignore flag
    unclipped = mot.gt_rows(scene, [0.040])
    assert unclipped[:, 2:4].min() < 0 or (unclipped[:, 2] + unclipped[:, 4]).max() > 96


def test_results_and_seqinfo(tmp_path):
    rows = np.array([[1, 3, 0.0, 4.5, 10, 6, 0.9], [2, 3, 1.25, 4.5, 10, 6, 1.0]])
    path = mot.write_results(tmp_path / "res.txt", rows)
    assert path.read_text().splitlines()[0] == "1,3,1,5.5,10,6,0.9,-1,-1,-1"
    np.testing.assert_allclose(mot.read_results(path), rows)
    mot.write_seqinfo(tmp_path / "seqinfo.ini", name="clip", n_frames=2, step_ticks=40, clock_hz=40_000.0,
                      width=96, height=64, classes={"truck": 1, "ball": 2})
    info = mot.read_seqinfo(tmp_path / "seqinfo.ini")
    assert info["frame_rate_hz"] == 1000.0 and info["step_ticks"] == 40 and info["classes"] == {"truck": 1, "ball": 2}


def test_bad_input(tmp_path):
    with pytest.raises(TruthUnavailable, match="no objects truth"):
        mot.gt_rows(StillScene(np.ones((4, 4))), [0.0])
    with pytest.raises(ViformError, match="frames must be whole numbers"):
        mot.write_results(tmp_path / "r.txt", [[0, 1, 0, 0, 1, 1, 1]])
    assert not (tmp_path / "r.txt").exists()
    (tmp_path / "bad.txt").write_text("1,2,3\n")
    with pytest.raises(ViformError, match="line 1 has 3 values"):
        mot.read_gt(tmp_path / "bad.txt")
    with pytest.raises(ViformError, match="step_ticks"):
        mot.step_times_s(3, 0, 40_000.0)
