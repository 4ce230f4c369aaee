"""What ``viform compare`` / ``demo`` tell a user: labels with the spike preset, frames longer than
the clip refused, valid JSON (no bare NaN), % and ms in the console table, grey error maps."""

import json
import math

import numpy as np
import pytest

from viform.light.catalog import builtin_scene
from viform.measure import comparison as cmp
from viform.report.compare_report import _fmt, figure_errors, finite_json, metrics_table, run_comparison


@pytest.fixture(scope="module")
def small():
    """Spike camera and the 33 ms overflow pixel on a tiny dilemma scene, 20 ms clip."""
    scene = builtin_scene("dilemma", 32, 64)
    return run_comparison(scene, 0.02, ["spikeone", "seed003-overflow", "cmos"], [0.006, 0.012], seed=2,
                          progress=False)


def test_spike_rows_name_the_preset_its_threshold_and_clock(small):
    sensor = cmp.make_compare_sensor("spikeone")
    p = sensor.parameters
    q = f"{p.threshold_electrons:,.0f}".replace(",", " ")
    rows = [s for s in small["shots"] if s.family == "spike"]
    assert rows
    for s in rows:
        assert f"Q = {q} e⁻" in s.label and f"{p.clock_hz / 1e3:g} kHz" in s.label


def test_one_spike_per_clip_light_is_q_over_eta_t(small):
    """A pixel fires every Q/(η·E) s, so once in T seconds at E = Q/(η·T); the ceiling is Q·f/η."""
    sensor, preset = cmp.make_compare_sensor("spikeone"), "spikeone"
    p = sensor.parameters
    note = cmp.spike_exposure_note(sensor, preset, 0.02)
    eta = p.optics.electrons_per_lux_second
    assert note["one_spike_per_clip_lux"] == pytest.approx(p.threshold_electrons / (eta * 0.02))
    assert note["ceiling_lux"] == pytest.approx(p.threshold_electrons * p.clock_hz / eta)
    assert f"{note['one_spike_per_clip_lux']:.3g} lux" in note["text"]


def test_frame_longer_than_the_clip_is_refused(small):
    """The overflow pixel integrates 33.3 ms: a 20 ms clip cannot hold one frame of it."""
    over = next(s for s in small["shots"] if s.key == "seed003-overflow")
    assert over.skipped and "longer than the clip" in over.skipped and "--duration" in over.skipped
    cmos = next(s for s in small["shots"] if s.key == "cmos")  # 10 ms frame fits: shown, inside the clip
    assert not cmos.skipped
    for est in cmos.estimates:
        assert est.source_time_s[1] <= 0.02 + 1e-12


def test_json_has_null_not_nan():
    doc = finite_json({"a": math.nan, "b": [1.0, math.inf, np.float64(-np.inf)], "c": {"d": np.float32(2.5)}})
    assert doc == {"a": None, "b": [1.0, None, None], "c": {"d": 2.5}}
    json.loads(json.dumps(doc, allow_nan=False))


def test_console_table_percent_and_ms_without_exponents():
    doc = {"sensors": {"x": {"label": "x", "skipped": None, "metrics": {
        "psnr_log_db": 20.0, "ssim_log": 0.5, "saturated_fraction": 0.05408, "underexposed_fraction": 0.001221,
        "edge_width_px": None, "flicker_error": 0.1, "dr_captured_db": 60.0, "data_rate_mb_per_s": 40.96,
        "latency_s": 6e-4}}}}
    table = metrics_table(doc)
    head, row = table.splitlines()
    assert "sat %" in head and "under %" in head and "latency ms" in head
    cells = row.split()
    assert "5.408" in cells and "0.1221" in cells and "0.6" in cells and "n/a" in cells
    assert "e-" not in row and "e+" not in row
    assert _fmt(1.3e-4) == "0.00013" and _fmt(1.234e-6) == "0.000001234" and "e" not in _fmt(1.2e7)


def test_error_map_draws_underexposed_pixels_as_missing(small):
    """Under-exposed pixels are masked (drawn grey), not painted as −2 decades."""
    fig = figure_errors(small, 0)
    shots = [s for s in small["shots"] if not s.skipped and s.lux_units]
    for ax, s in zip(fig.axes, shots, strict=False):
        data = ax.images[0].get_array()
        under = s.estimates[0].underexposed
        assert np.array_equal(np.ma.getmaskarray(data), under)
    import matplotlib.pyplot as plt

    plt.close(fig)
