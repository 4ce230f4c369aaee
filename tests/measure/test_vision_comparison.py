"""The compare vision section: every sensor tracked by one back end, scored at its own instants."""

import numpy as np
import pytest

from viform.measure import comparison as cmp
from viform.measure.vision_comparison import figure_tracks, vision_html, vision_json, vision_scores
from viform.sensors.spike import SpikeSensor

pytest.importorskip("trackeval")


def test_spike_and_frame_rows_table_verdict_figure():
    from viform.light.multi_object import MultiObjectScene

    scene = MultiObjectScene(48, 64, brightness=3.0)
    duration = 0.04
    stream = SpikeSensor(threshold_electrons=100).capture(scene, duration, seed=1)
    cmos = cmp.make_compare_sensor("cmos-short")
    stack = cmos.capture(scene, duration, seed=1)
    shots = [cmp.Shot("spike-interval", "spike (Q = 100 e⁻) · interval", "", raw=stream, frame_rate_hz=40e3,
                      name="spike", family="spike"),
             cmp.Shot("cmos-short", "CMOS 1 ms", "", raw=stack, frame_rate_hz=30.0, name="cmos-short", family="frame",
                      sensor=cmos)]
    vision = vision_scores({"scene": scene, "shots": shots, "duration_s": duration})
    assert set(vision) == {"spike", "cmos-short", "_truth"}
    assert vision["spike"]["frames"] == 160  # every 10 ticks over 1,600 ticks
    assert vision["cmos-short"]["frames"] == 1  # 30 fps: one frame in 40 ms, read at the end of its 1 ms
    np.testing.assert_allclose(vision["cmos-short"]["times_s"], [1e-3])
    # one frame shows no motion: at most what stands out from the background around it (the start-up
    # priming) is found; the rest is missed, and the report says why
    cmos_scores = vision["cmos-short"]["scores"]
    assert len(cmos_scores["never_found"]) >= 4 and len(cmos_scores["objects"]) == 6
    doc = vision_json(vision)
    assert [r["key"] for r in doc["table"]] == ["spike", "cmos-short"]
    assert doc["verdict"][0].startswith("Tracking: best HOTA")
    assert "<section id='vision'>" in vision_html(vision, "<img>")
    import matplotlib.pyplot as plt

    plt.close(figure_tracks(vision))
    # the one frame is named as the cause, with its number
    causes = vision["cmos-short"]["causes"]
    assert set(causes) == set(cmos_scores["never_found"])
    assert all(c.startswith("only 1 frame(s) in the clip") for c in causes.values())
    assert "only 1 frame(s) in the clip" in vision_html(vision, "<img>")
    # the spike rows carry the sensor's detectability: a score over the objects it shows
    assert vision["spike"]["scores"]["detectable"] is not None


def _row(label, hota, never, objects=6, latency=1.0):
    return {"key": label, "label": label, "hota": hota, "mota": 0.5, "idf1": 0.5, "id_switches": 0,
            "median_latency_ms": latency, "never_found": never, "objects": objects, "causes": {}}


def test_verdict_names_ties():
    from viform.measure.vision_comparison import vision_verdict

    rows = [_row("spike", 0.7, [7])] + [_row(f"frame {k}", 0.0, [1, 2, 3, 4, 5, 6], latency=None) for k in range(7)]
    lines = vision_verdict(rows)
    never = next(line for line in lines if line.startswith("Most objects never matched"))
    assert "7-way tie" in never and "frame 0, frame 1, frame 2 and 4 more" in never
    assert lines[0] == "Tracking: best HOTA 0.70 by spike (MOTA 0.50, IDF1 0.50)."
    tie = vision_verdict([_row("a", 0.5, []), _row("b", 0.5, [])])
    assert tie[0] == "Tracking: best HOTA 0.50, a 2-way tie: a, b." and "2-way tie: a, b" in tie[1]
    alone = vision_verdict([_row("a", 0.5, [1, 2]), _row("b", 0.6, [1])])
    assert "Most objects never matched: a, 2 of 6 (ids 1, 2)." in alone


def test_causes_name_the_physics():
    from viform.light.multi_object import MultiObjectScene
    from viform.measure.vision_comparison import _causes

    scene = MultiObjectScene(125, 200)
    gt = np.array([[1, 3, 0, 0, 5, 3, 1, 1, 1, 2.5], [1, 7, 0, 0, 6, 4, 1, 1, 1, 0.2], [1, 5, 0, 0, 6, 15, 1, 1, 1, 9]])
    scores = {"never_found": [3, 5, 7]}
    causes = _causes(scores, gt, 30, 1e-3, scene)
    assert causes[7].startswith("its contrast is under the noise (detectability at most 0.20")
    # the bullet (5,000 px/s at 200 px): 1 ms smears it over 5 px, as wide as it is
    assert causes[3].startswith("the exposure's blur: 1 ms at 5,000 px/s smears it over 5 px")
    assert causes[5] == "missed by the tracker (the sensor shows it)"
    assert _causes(scores, gt, 2, 1e-3, scene)[5].startswith("only 2 frame(s)")
