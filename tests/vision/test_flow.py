"""Optical flow from spikes (viform.vision.flow): files, scores, and the estimator against exact truth."""

from __future__ import annotations

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.catalog import builtin_scene
from viform.light.truth import FlowTruth
from viform.sensors.spike import SpikeSensor
from viform.vision.flow import (
    check_interval,
    estimate_flow,
    flow_scores,
    flow_sequence,
    layered_refinement,
    motion_scores,
    read_flo,
    spike_rate_images,
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


def test_interval_messages_name_the_library_parameters():
    spikes = SpikeSensor(threshold_electrons=100).capture(builtin_scene("translating", height=16, width=24),
                                                          0.002, seed=0)
    for t, dt, name in ((0.001, -1.0, "dt_s"), (0.5, 0.001, "t_s")):
        with pytest.raises(ViformError, match=name) as info:
            check_interval(spikes, t, dt)
        assert "--" not in str(info.value)
    with pytest.raises(ViformError, match="refine = 'magic'"):
        estimate_flow(spikes, 0.0005, 0.0005, refine="magic")


def test_one_pass_images_equal_multi_interval_imaging():
    from viform.imaging.multi_interval import multi_interval_rate

    sensor = SpikeSensor(threshold_electrons=100, clock_hz=40e3)
    spikes = sensor.capture(builtin_scene("rotating", height=24, width=32, min_lux=1.0, max_lux=20.0), 0.01, seed=4)
    ticks = [3, 40, 40, 80, 200, 390]
    images = list(spike_rate_images(spikes, ticks))
    assert [k for k, _ in images] == ticks
    for k, image in images:
        rate, used, censored = multi_interval_rate(spikes, k, 4, adaptive=True)
        np.testing.assert_allclose(image.rate, rate, rtol=1e-6)  # float32
        assert np.array_equal(image.intervals, used) and np.array_equal(image.censored, censored)


def test_motion_scores_split_moving_objects_and_still_background():
    flow = np.zeros((2, 4, 6))
    flow[0, :2, :2] = 3.0  # object 1 moves 3 px right; the rest stands still
    labels = np.zeros((4, 6), int)
    labels[:2, :2] = 1
    truth = FlowTruth(flow, np.ones((4, 6), bool), 0.0, 1.0)
    zero = motion_scores(np.zeros_like(flow), truth, labels, {1: "car"})
    assert zero.moving.pixels == 4 and zero.moving.relative_error == pytest.approx(1.0)
    assert zero.still_pixels == 20 and zero.still_median_px == 0.0
    estimate = flow.copy()
    estimate[0, :2, :2] = 2.4  # 80 % of the motion
    estimate[1, 3, :] = 0.5  # false motion on 6 of 20 still pixels
    s = motion_scores(estimate, truth, labels, {1: "car"})
    assert s.moving.epe_px == pytest.approx(0.6) and s.moving.relative_error == pytest.approx(0.2)
    assert s.objects["1 car"].epe_px == pytest.approx(0.6)
    assert s.still_median_px == 0.0 and s.still_p95_px == pytest.approx(0.5)
    assert s.all.epe_px == pytest.approx((4 * 0.6 + 6 * 0.5) / 24)


def _moving_square(shift_px, size=(48, 64), seed=0):
    """Log light of a uniform bright square moving over a textured still wall, with noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size[0], 0:size[1]].astype(float)
    wall = np.log(5.0 + 2.0 * np.sin(x / 3.0) * np.sin(y / 4.0))
    sigma = 0.03
    images = []
    for dx, dy in ((0.0, 0.0), shift_px):
        log = wall.copy()
        log[(y >= 14 + dy) & (y < 30 + dy) & (x >= 20 + dx) & (x < 36 + dx)] = np.log(40.0)
        images.append(log + rng.normal(0, sigma, size))
    truth = np.zeros((2, *size))
    inside = (y >= 14) & (y < 30) & (x >= 20) & (x < 36)
    truth[0][inside], truth[1][inside] = shift_px
    return images, np.full(size, sigma ** 2), inside, truth


@pytest.mark.parametrize("shift", [(3.0, 0.0), (-2.0, 5.0), (9.0, 1.0)])
def test_layered_refinement_moves_a_uniform_region_and_stills_the_wall(shift):
    # a uniform square: its interior says nothing about its motion, only its edges do; a dense flow of
    # zeros (a flow that missed it) is refined to the square's motion, the wall to exactly zero
    (log0, log1), var, inside, truth = _moving_square(shift)
    dense = np.zeros((2, *log0.shape))
    dense[:, 5, 5] = 0.2  # spill on the still wall
    flow, regions, info = layered_refinement(log0, log1, var, var, dense)
    assert len(regions) == 1
    np.testing.assert_allclose(flow[0][inside], shift[0], atol=0.1)
    np.testing.assert_allclose(flow[1][inside], shift[1], atol=0.1)
    # the wall that stays visible at t1 is still: zero flow
    y, x = np.mgrid[0:log0.shape[0], 0:log0.shape[1]]
    covered = (y >= 14 + shift[1]) & (y < 30 + shift[1]) & (x >= 20 + shift[0]) & (x < 36 + shift[0])
    wall = ~inside & ~covered
    assert np.count_nonzero(flow[:, wall]) == 0


def test_estimator_beats_its_dense_flow_on_independent_motion():
    # multi-object at Q = 100 (200×125): objects over a still textured wall; the layered estimate must
    # cut the dense flow's error on moving pixels at least in half and keep the wall still
    sensor = SpikeSensor(threshold_electrons=100, clock_hz=40e3)
    scene = builtin_scene("multi-object", height=125, width=200)
    spikes = sensor.capture(scene, 0.012, seed=5)
    layered = estimate_flow(spikes, 0.008, 0.001)
    dense = estimate_flow(spikes, 0.008, 0.001, refine="none")
    truth = scene.optical_flow_px(layered.t0_s, layered.t1_s)
    labels = scene.object_labels(layered.t0_s)
    a, b = motion_scores(layered.flow_px, truth, labels), motion_scores(dense.flow_px, truth, labels)
    assert a.moving.pixels > 500
    assert a.moving.epe_px < 0.5 * b.moving.epe_px
    assert a.still_median_px <= 0.05 < b.still_median_px
    assert layered.confidence.shape == labels.shape and 0 <= layered.confidence.min() <= 1


def test_confidence_is_low_where_spikes_are_few():
    # left half bright (0.5 spikes a tick), right half dim (≈ 0.005): the dim half cannot resolve 1 ms
    sensor = SpikeSensor(threshold_electrons=100, clock_hz=40e3)
    bright = float(sensor.parameters.optics.lux_from_electrons_per_s(0.5 * 100 * 40e3))
    lux = np.full((16, 32), bright)
    lux[:, 16:] = bright / 100
    from viform.light.scenes import StillScene

    spikes = sensor.capture(StillScene(lux), 0.02, seed=2)
    est = estimate_flow(spikes, 0.009, 0.001)
    assert np.median(est.confidence[:, :16]) == 1.0
    assert np.median(est.confidence[:, 16:]) < 0.2


def test_chained_steps_compose():
    from viform.vision.flow import compose_flows

    first = np.zeros((2, 8, 20))
    first[0] = 1.0  # every pixel 1 px right
    second = np.zeros((2, 8, 20))
    second[0] = np.arange(20) / 10.0  # then x/10 px right, read where the first step left it
    expected = np.tile(1.0 + (np.arange(18) + 1.0) / 10.0, (8, 1))
    np.testing.assert_allclose(compose_flows(first, second)[0][:, :18], expected, rtol=1e-6)
    sensor = SpikeSensor(threshold_electrons=100, clock_hz=40e3)
    spikes = sensor.capture(builtin_scene("translating", height=32, width=48, velocity_px_per_s=(6000.0, 0.0),
                                          min_lux=2.0, max_lux=20.0), 0.004, seed=1)
    chained = estimate_flow(spikes, 0.001, 0.001, chain_steps=4, chain_above_px=1.0, refine="none")
    assert chained.info["chained_steps"] == 4
    assert estimate_flow(spikes, 0.001, 0.001).info["chained_steps"] == 1


@pytest.mark.parametrize("k_side, adaptive", [(4, True), (2, False), (1, True)])
def test_one_pass_images_equal_multi_interval_imaging_on_any_width(k_side, adaptive):
    """Widths not a multiple of 8 (the padded last word), more pixels than one chunk (1,024), dark
    pixels (censored on both sides), a pixel firing every tick, instants at both ends and repeated."""
    from viform.imaging.multi_interval import multi_interval_rate
    from viform.stream.container import SpikeStream

    rng = np.random.default_rng(11)
    rate = rng.choice([0.0, 0.003, 0.05, 0.3, 0.8], size=(37, 53))
    rate[0, :5] = 0.0
    rate[1, 1] = 1.0
    spikes = SpikeStream(rng.random((600, 37, 53)) < rate, 40e3, 100.0)
    ticks = [0, 1, 1, 64, 65, 200, 263, 599]
    images = list(spike_rate_images(spikes, ticks, spikes_per_side=k_side, adaptive=adaptive, horizon_ticks=600))
    assert [k for k, _ in images] == ticks
    for k, image in images:
        expected, used, censored = multi_interval_rate(spikes, k, k_side, adaptive=adaptive)
        np.testing.assert_allclose(image.rate, expected, rtol=1e-6)  # float32
        assert np.array_equal(image.intervals, used) and np.array_equal(image.censored, censored)
    assert images[0][1].censored[0, :5].all()  # no spike at all: censored
