"""TrackEval wiring on hand-made cases whose scores are known by hand."""

import numpy as np
import pytest

from viform.vision.metrics import score_tracking, trackeval_scores

pytest.importorskip("trackeval")


def _gt():
    rows = []
    for k in range(1, 5):
        rows.append((k, 1, 10.0 * k, 5.0, 8.0, 8.0, 1, 1, 1.0))  # A moves right 10 px a frame
        rows.append((k, 2, 60.0, 30.0, 6.0, 10.0, 1, 2, 1.0))  # B stands still
    return np.array(rows)


def _result(gt, ids):
    return np.array([(r[0], ids(r), *r[2:6], 1.0) for r in gt])


def test_perfect_tracking_scores_one():
    gt = _gt()
    s = trackeval_scores(gt, _result(gt, lambda r: r[1]), 4)
    assert (s["hota"], s["mota"], s["idf1"], s["id_switches"]) == (pytest.approx(1.0), 1.0, 1.0, 0)


def test_one_id_switch():
    # A is reported as track 1 in frames 1-2, as track 3 in frames 3-4; B is perfect.
    # MOTA = 1 − 1/8; IDF1 = 2·6/16 (A's best identity covers 2 of its 4 boxes);
    # AssA = (4·0.5 + 4·1)/8 = 0.75 and DetA = 1, so HOTA = √0.75.
    gt = _gt()
    s = trackeval_scores(gt, _result(gt, lambda r: (3 if r[0] > 2 else 1) if r[1] == 1 else 2), 4)
    assert s["id_switches"] == 1
    assert s["mota"] == pytest.approx(0.875)
    assert s["idf1"] == pytest.approx(0.75)
    assert s["assa"] == pytest.approx(0.75) and s["deta"] == pytest.approx(1.0)
    assert s["hota"] == pytest.approx(np.sqrt(0.75))


def test_miss_hidden_rows_latency_and_error():
    gt = _gt()
    gt[(gt[:, 0] == 1) & (gt[:, 1] == 2), 6] = 0  # B hidden in frame 1: ignored
    res = _result(gt, lambda r: r[1])
    res = res[~((res[:, 0] <= 2) & (res[:, 1] == 1))]  # A reported from frame 3 only
    res[:, 2] += np.where(res[:, 1] == 2, 1.0, 0.0)  # B's box 1 px off: IoU 5·10/(7·10) ≥ 0.5
    times = np.array([0.001, 0.002, 0.003, 0.004])
    s = score_tracking(gt, res, times, clock_hz=40_000.0)
    # hidden B need not be found: the box on it in frame 1 is neither a hit nor a false positive
    assert s["false_negatives"] == 2 and s["false_positives"] == 0 and s["gt_boxes"] == 7
    assert s["mota"] == pytest.approx(1 - 2 / 7)
    assert s["detectable"] is None  # nine columns: no detectability known
    # a box elsewhere in frame 1 is a false positive
    stray = np.vstack([res, [1, 9, 80.0, 80.0, 5.0, 5.0, 1.0]])
    assert score_tracking(gt, stray, times)["false_positives"] == 1
    a, b = s["objects"][1], s["objects"][2]
    assert a["latency_found_ticks"] == 120 and a["latency_match_ticks"] == 120  # appeared at 0, found at 3 ms
    assert b["appear_s"] == 0.001 and b["latency_match_ticks"] == 40  # visible from frame 2, found then
    assert b["position_error_px"] == pytest.approx(1.0) and a["position_error_px"] == 0.0
    assert a["speed_px_per_s"] == pytest.approx(10_000.0) and s["never_found"] == []


def test_scores_over_the_detectable_objects_excuse_what_the_sensor_did_not_show():
    # B is under detectability 1 in frames 1-2 (the sensor's pixels cannot show it yet), then above;
    # the tracker finds it from frame 3: over all objects two misses, over the detectable ones none
    gt = np.column_stack([_gt(), np.full(8, 5.0)])
    gt[(gt[:, 1] == 2) & (gt[:, 0] <= 2), 9] = 0.3
    res = _result(gt, lambda r: r[1])
    res = res[~((res[:, 1] == 2) & (res[:, 0] <= 2))]
    times = np.array([0.001, 0.002, 0.003, 0.004])
    s = score_tracking(gt, res, times, clock_hz=40_000.0)
    assert s["false_negatives"] == 2 and s["mota"] == pytest.approx(0.75)
    d = s["detectable"]
    assert d["false_negatives"] == 0 and d["mota"] == 1.0 and d["hota"] == pytest.approx(1.0)
    assert d["undetectable_rows"] == 2 and d["never_detectable"] == []
    assert d["objects"][2]["appear_s"] == 0.002 and d["objects"][2]["latency_match_ticks"] == 40
    # a box on an undetectable object is not held against the tracker either
    full = _result(gt, lambda r: r[1])
    assert score_tracking(gt, full, times)["detectable"]["false_positives"] == 0


def test_speed_is_the_objects_not_the_clipped_boxes():
    # an object at 10 px a frame leaving the image (width 40): its clipped box's centre slows down
    rows = []
    for k in range(1, 7):
        x = 10.0 * k
        w = min(x + 8.0, 40.0) - x
        if w > 0:
            rows.append((k, 1, x, 5.0, w, 8.0, 1, 1, 1.0))
    times = np.arange(1, 7) * 1e-3
    s = score_tracking(np.array(rows), np.zeros((0, 7)), times)
    assert s["objects"][1]["speed_px_per_s"] == pytest.approx(10_000.0)
