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
    assert float(line[2]) == pytest.approx(first[1].x_px + 1, abs=1e-4) and len(line) == 10
    assert line[9] == "-1"  # no sensor given: detectability unknown
    back = mot.read_gt(path)
    np.testing.assert_allclose(back, rows, atol=1e-4)
    assert not list(tmp_path.glob(".*"))  # no temporary left
    # nine-column files (other tools) read with detectability unknown
    nine = tmp_path / "nine.txt"
    nine.write_text("1,1,2,3,4,5,1,1,1\n")
    assert mot.read_gt(nine).tolist() == [[1, 1, 1, 2, 4, 5, 1, 1, 1, -1]]


def test_boxes_clipped_to_the_image_visible_fraction_and_ignore_flag():
    scene = builtin_scene("multi-object", height=64, width=96)
    rows = mot.gt_rows(scene, [scene.t_ref_s, 0.040, 0.043])
    assert np.all(rows[:, 2:4] >= 0) and np.all(rows[:, 2] + rows[:, 4] <= 96 + 1e-9)
    assert np.all(rows[:, 3] + rows[:, 5] <= 64 + 1e-9)
    ball = rows[(rows[:, 0] == 1) & (rows[:, 1] == 2)][0]
    assert ball[6] == 0 and ball[8] == 0  # fully hidden: need not be found
    # an object partly outside: the box is the part inside, the visibility the fraction of the whole
    leaving = {o.object_id: o for o in scene.objects(0.043)}
    car = leaving[4]
    assert car.x_px < 0
    r = rows[(rows[:, 0] == 3) & (rows[:, 1] == 4)][0]
    assert r[2] == 0 and r[4] == pytest.approx(car.width_px + car.x_px)
    assert r[8] == pytest.approx(car.visible_fraction) and r[8] < 1


def test_near_integers_print_without_a_trailing_dot(tmp_path):
    rows = np.array([[10, 7, 361.5, 11.00000001, 12, 8, 1, 6, 1.0, 2.0]])
    text = mot.write_gt(tmp_path / "gt.txt", rows).read_text().strip()
    assert text == "10,7,362.5,12,12,8,1,6,1,2"
    assert ".," not in text and not text.endswith(".")
    res = mot.write_results(tmp_path / "r.txt", [[1, 2, 3.99999999, 0.5, 2, 3, 1]]).read_text().strip()
    assert res == "1,2,5,1.5,2,3,1,-1,-1,-1"


def test_detectability_column_is_the_charge_against_q():
    from viform.vision.detectability import SpikeDetectability

    scene = builtin_scene("multi-object", height=250, width=400)
    eta, q = 286_347.6, 16_250.0
    rows = mot.gt_rows(scene, [0.010, 0.020], detectability=SpikeDetectability(q, eta))
    bird = rows[(rows[:, 1] == 7) & (rows[:, 0] == 2)][0]
    # the bird (1.5 lux over ≈ 5 lux, 3,606 px/s, 12 × 8 px): dwell min(12/3000, 8/2000) s
    objs = {o.object_id: o for o in scene.objects(0.020)}
    b = objs[7]
    expected = eta * abs(b.lux - b.background_lux) * min(12 / 3000, 8 / 2000) / q
    assert bird[9] == pytest.approx(expected, rel=1e-9) and bird[9] < 1
    # in view since the stream started: the charge grows with the time seen, up to the dwell
    # (the pedestrian: 100 px/s, so its dwell, 0.3 s, is longer than the clip)
    for k, t in enumerate((0.010, 0.020), start=1):
        p = {o.object_id: o for o in scene.objects(t)}[5]
        row = rows[(rows[:, 1] == 5) & (rows[:, 0] == k)][0]
        assert row[9] == pytest.approx(eta * abs(p.lux - p.background_lux) * t / q, rel=1e-9)


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


def test_class_ids_by_first_appearance_and_one_objects_call_per_instant():
    """Without class ids, gt_rows numbers the classes as class_ids_of does (by first appearance, objects in id
    order), from the same objects it writes: one objects() call per instant, not two."""
    from viform.light.truth import ObjectTruth

    class Appearing(StillScene):
        calls = 0

        def truth_kinds(self):
            return ("objects",)

        def objects(self, t_s):
            Appearing.calls += 1
            found = [ObjectTruth(5, "vehicle", 1.0, 1.0, 3.0, 2.0, 1.0, (0.0, 0.0))]
            if t_s > 0.002:  # a lower id with a new class appears later: ids follow appearance, not object ids
                found.append(ObjectTruth(2, "person", 4.0, 4.0, 2.0, 2.0, 0.5, (0.0, 0.0)))
            return found[::-1]

    scene = Appearing(np.ones((16, 16)))
    times = [0.001, 0.002, 0.003]
    assert mot.class_ids_of(scene, times) == {"vehicle": 1, "person": 2}
    Appearing.calls = 0
    rows = mot.gt_rows(scene, times)
    assert Appearing.calls == len(times)
    assert np.array_equal(rows, mot.gt_rows(scene, times, mot.class_ids_of(scene, times)))
    assert rows[:, 7].tolist() == [1, 1, 2, 1]  # frame 3: the person (object 2) first, then the vehicle


def test_rows_and_their_class_ids_from_one_pass():
    """return_class_ids gives class_ids_of's ids beside the same rows, with one objects() call per instant."""
    scene = builtin_scene("multi-object", height=64, width=96)
    times = mot.step_times_s(30, 40, 40_000.0)
    calls = []
    objects = scene.objects
    scene.objects = lambda t_s: calls.append(t_s) or objects(t_s)
    rows, classes = mot.gt_rows(scene, times, return_class_ids=True)
    assert len(calls) == len(times)
    assert classes == mot.class_ids_of(scene, times) and len(classes) >= 2
    assert np.array_equal(rows, mot.gt_rows(scene, times, classes))
