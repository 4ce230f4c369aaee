"""Optical flow from spikes (viform.vision.flow): files, scores, and the estimator against exact truth."""

from __future__ import annotations

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.catalog import builtin_scene
from viform.light.truth import FlowTruth
from viform.sensors.spike import SpikeSensor
from viform.vision.flow import (
    estimate_flow,
    flow_scores,
    flow_sequence,
    read_flo,
    textured_mask,
    write_flo,
)


def test_flo_round_trip_marks_unknown(tmp_path):
    rng = np.random.default_rng(0)
    flow = rng.normal(0, 5, (2, 7, 11))
    valid = rng.random((7, 11)) > 0.3
    flow[0, 0, 0] = np.nan  # not finite: unknown too
    write_flo(tmp_path / "f.flo", flow, valid)
    raw = (tmp_path / "f.flo").read_bytes()
    assert np.frombuffer(raw[:4], "<f4")[0] == 202021.25 and len(raw) == 12 + 8 * 77
    back, known = read_flo(tmp_path / "f.flo")
    expected = valid & np.isfinite(flow).all(0)
    assert np.array_equal(known, expected)
    np.testing.assert_allclose(back[:, known], flow[:, known].astype(np.float32))
    (tmp_path / "bad.flo").write_bytes(raw[:-8])
    with pytest.raises(ViformError, match="does not match"):
        read_flo(tmp_path / "bad.flo")


def test_scores_on_a_hand_made_case():
    truth = FlowTruth(np.zeros((2, 2, 2)), np.array([[True, True], [True, False]]), 0.0, 1.0)
    truth.flow_px[0] = 10.0  # 10 px to the right everywhere
    estimate = np.zeros((2, 2, 2))
    estimate[0] = [[10.0, 10.4], [14.0, 99.0]]  # errors 0, 0.4, 4 (outlier: > 3 px and > 0.5 px), invalid
    scores = flow_scores(estimate, truth)
    assert scores.pixels == 3
    assert scores.epe_px == pytest.approx((0 + 0.4 + 4) / 3)
    assert scores.fl_outliers == pytest.approx(1 / 3)
    assert scores.true_flow_px == pytest.approx(10.0)


@pytest.mark.parametrize("velocity", [(2000.0, 0.0), (-1200.0, 1600.0)])
def test_estimator_recovers_translation_at_q100(velocity):
    # Q = 100 e-, the texture spans 0.5–5 spikes per 10 ticks: intervals of 2–20 ticks
    sensor = SpikeSensor(threshold_electrons=100, clock_hz=40e3)
    top = float(sensor.parameters.optics.lux_from_electrons_per_s(0.5 * 100 * 40e3))
    scene = builtin_scene("translating", height=64, width=96, velocity_px_per_s=velocity,
                          min_lux=0.1 * top, max_lux=top)
    spikes = sensor.capture(scene, 0.008, seed=3)
    estimate = estimate_flow(spikes, 0.003, 0.001)
    truth = scene.optical_flow_px(estimate.t0_s, estimate.t1_s)
    mask = textured_mask(scene.illuminance_lux(estimate.t0_s), margin_px=8)
    scores = flow_scores(estimate.flow_px, truth, mask)
    assert scores.pixels > 1000
    assert scores.epe_px < 0.5 and scores.fl_outliers < 0.01
    assert np.hypot(*velocity) * 1e-3 == pytest.approx(scores.true_flow_px, rel=1e-9)


def test_sequence_gives_the_single_instant_flows():
    sensor = SpikeSensor(threshold_electrons=100, clock_hz=40e3)
    scene = builtin_scene("rotating", height=48, width=64, min_lux=2.0, max_lux=40.0)
    spikes = sensor.capture(scene, 0.004, seed=1)
    pairs = list(flow_sequence(spikes, 40, start_tick=10))
    assert [(a, b) for a, b, _ in pairs] == [(10 + 40 * k, 50 + 40 * k) for k in range(len(pairs))]
    single = estimate_flow(spikes, (50 + 0.5) / 40e3, 40 / 40e3)
    np.testing.assert_allclose(pairs[1][2], single.flow_px, atol=1e-5)


def test_interval_and_instants_are_checked():
    spikes = SpikeSensor(threshold_electrons=100).capture(builtin_scene("translating", height=16, width=24),
                                                          0.002, seed=0)
    with pytest.raises(ViformError, match="dt_s = 0 is not allowed"):
        estimate_flow(spikes, 0.001, 0)
    with pytest.raises(ViformError, match="past the stream's end"):
        estimate_flow(spikes, 0.001, 0.0015)
    with pytest.raises(ViformError, match="same tick"):
        estimate_flow(spikes, 0.001, 1e-6)
