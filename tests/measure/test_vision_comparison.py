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
    # a change detector needs a frame to compare with: one frame finds nothing
    cmos_scores = vision["cmos-short"]["scores"]
    assert cmos_scores["never_found"] == sorted(cmos_scores["objects"]) and len(cmos_scores["objects"]) == 6
    doc = vision_json(vision)
    assert [r["key"] for r in doc["table"]] == ["spike", "cmos-short"]
    assert doc["verdict"][0].startswith("Tracking: best HOTA")
    assert "<section id='vision'>" in vision_html(vision, "<img>")
    import matplotlib.pyplot as plt

    plt.close(figure_tracks(vision))
