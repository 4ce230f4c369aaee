"""Ground truth of the built-in scenes (motion, flow, depth, objects) against their rendered light."""

import math

import numpy as np
import pytest
from scipy.ndimage import map_coordinates, maximum_filter, minimum_filter

from viform.light.catalog import builtin_scene
from viform.light.scenes import StillScene, VideoScene
from viform.light.truth import TruthUnavailable, disc_fraction_inside


def _residual_vs_contrast(scene, t0, t1, smooth_fraction=0.1):
    """Brightness-constancy residual |L(p + flow, t1) − L(p, t0)| over the local contrast, on smooth
    valid pixels (bilinear interpolation of the rendered light at t1)."""
    flow = scene.optical_flow_px(t0, t1)
    l0, l1 = scene.illuminance_lux(t0), scene.illuminance_lux(t1)
    y, x = np.mgrid[0:scene.height, 0:scene.width].astype(float)
    warped = map_coordinates(l1, [y + flow.flow_px[1], x + flow.flow_px[0]], order=1, mode="nearest")
    span = l0.max() - l0.min()
    local = maximum_filter(l0, 5) - minimum_filter(l0, 5)
    # smooth = no step edge within the interpolation's reach (checkerboard edges are not bilinear)
    smooth = (maximum_filter(l0, 3) - minimum_filter(l0, 3)) < smooth_fraction * span
    dest = map_coordinates(smooth.astype(float), [y + flow.flow_px[1], x + flow.flow_px[0]], order=0) > 0
    use = flow.valid & smooth & dest & (local > 0.01 * span)
    return np.abs(warped - l0)[use] / local[use], use


@pytest.mark.parametrize("name, kw", [("translating", {"velocity_px_per_s": (8000.0, -3000.0)}),
                                      ("translating", {"velocity_px_per_s": (500.0, 0.0)}),
                                      ("rotating", {}), ("rotating", {"angular_speed_rad_per_s": -40.0})])
def test_pattern_flow_keeps_brightness(name, kw):
    scene = builtin_scene(name, height=60, width=90, **kw)
    ratio, use = _residual_vs_contrast(scene, 0.003, 0.0032)
    assert use.sum() > 0.2 * use.size
    # bilinear interpolation of the rendered light limits the check (exact cases below)
    assert np.median(ratio) < 0.01 and np.percentile(ratio, 99) < 0.03


def test_rotation_by_a_quarter_turn_is_exact():
    scene = builtin_scene("rotating", height=40, width=60, angular_speed_rad_per_s=2 * np.pi * 5)
    t0, t1 = 0.004, 0.004 + 0.25 / 5  # a quarter turn maps pixel centres onto pixel centres
    flow = scene.optical_flow_px(t0, t1)
    rows, cols = np.nonzero(flow.valid)
    assert rows.size > 0.5 * flow.valid.size
    r1 = np.rint(rows + flow.flow_px[1][flow.valid]).astype(int)
    c1 = np.rint(cols + flow.flow_px[0][flow.valid]).astype(int)
    np.testing.assert_allclose(scene.illuminance_lux(t1)[r1, c1], scene.illuminance_lux(t0)[rows, cols],
                               rtol=1e-9)


def test_translation_by_whole_pixels_is_exact():
    scene = builtin_scene("translating", height=40, width=50, velocity_px_per_s=(4000.0, -2000.0))
    flow = scene.optical_flow_px(0.001, 0.002)  # (4, -2) px exactly
    assert np.array_equal(flow.flow_px[0][flow.valid], np.full(flow.valid.sum(), 4.0))
    l0, l1 = scene.illuminance_lux(0.001), scene.illuminance_lux(0.002)
    rows, cols = np.nonzero(flow.valid)
    np.testing.assert_allclose(l1[rows - 2, cols + 4], l0[rows, cols], rtol=1e-12)
    # the points leaving the field are exactly the last 4 columns and the first 2 rows
    expected = np.ones((40, 50), bool)
    expected[:, -4:] = False
    expected[:2] = False
    assert np.array_equal(flow.valid, expected)


@pytest.mark.parametrize("name", ["rotating", "dilemma", "waving-hand"])
def test_velocity_is_the_flow_over_a_short_interval(name):
    scene = builtin_scene(name, height=64, width=96)
    t, dt = 0.0123, 1e-8  # flow/dt differs from the velocity by |acceleration|·dt/2 ≤ 1e-3 px/s here
    motion = scene.motion_px_per_s(t)
    flow = scene.optical_flow_px(t, t + dt)
    both = flow.valid & np.all(np.isfinite(motion), axis=0)
    assert both.mean() > 0.5
    np.testing.assert_allclose(flow.flow_px[:, both] / dt, motion[:, both], atol=3e-3)


def test_dilemma_labels_match_the_rendered_moving_parts_and_boxes():
    scene = builtin_scene("dilemma", height=64, width=128)
    for t in (0.0, 0.0071, 0.0305):
        labels = scene.object_labels(t)
        moving = scene.moving_mask(t)
        blade_or_vehicle = np.isin(labels, (1, 2, 3, 4))
        # the small object is drawn over everything; elsewhere the labels are the renderer's own masks
        assert np.array_equal(blade_or_vehicle, moving & (labels != 5))
        for obj in scene.objects(t):
            rows, cols = np.nonzero(labels == obj.object_id)
            if obj.visible_fraction == 0 or rows.size == 0:
                continue
            # every labelled pixel centre (c + 0.5, r + 0.5) lies in the analytic box, and the box is tight
            x0, y0, x1, y1 = obj.x_px, obj.y_px, obj.x_px + obj.width_px, obj.y_px + obj.height_px
            assert (cols + 0.5 >= x0 - 1e-9).all() and (cols + 0.5 <= x1 + 1e-9).all()
            assert (rows + 0.5 >= y0 - 1e-9).all() and (rows + 0.5 <= y1 + 1e-9).all()
            visible_x0, visible_x1 = max(x0, 0), min(x1, scene.width)
            assert cols.min() - visible_x0 < 1.0 + 1e-9 and visible_x1 - (cols.max() + 1) < 1.0 + 1e-9
            assert rows.min() - y0 < 1.0 + 1e-9 and y1 - (rows.max() + 1) < 1.0 + 1e-9


def test_dilemma_object_velocities_follow_the_boxes():
    scene = builtin_scene("dilemma", height=64, width=128)
    t, dt = 0.004, 1e-6
    before = {o.object_id: o for o in scene.objects(t - dt)}
    for obj in scene.objects(t):
        if obj.class_name in ("vehicle", "small object", "led"):  # pure translation: the box centre's speed
            prev = before[obj.object_id]
            vx = (obj.x_px - prev.x_px) / dt
            assert vx == pytest.approx(obj.velocity_px_per_s[0], rel=1e-6, abs=1e-3)
    vehicle = scene.objects(t)[0]
    # the step edge the blur metric uses sits at the box's right side
    lux = scene.illuminance_lux(t)
    row = (scene.vehicle_rows[0] + scene.vehicle_rows[1]) // 2
    right_edge_col = int(np.nonzero(lux[row] == scene.vehicle_lux)[0].max())
    assert right_edge_col + 1 == pytest.approx(vehicle.x_px + vehicle.width_px, abs=1.0)


def test_occluded_background_is_invalid_and_leaving_points_too():
    scene = builtin_scene("dilemma", height=64, width=128)
    t0, t1 = 0.01, 0.012
    flow = scene.optical_flow_px(t0, t1)
    labels0, labels1 = scene.object_labels(t0), scene.object_labels(t1)
    covered = (labels0 == 0) & np.isin(labels1, (1, 2, 3, 4, 5))
    assert covered.any() and not flow.valid[covered].any()
    vehicle = labels0 == 1
    leaving = vehicle & (np.mgrid[0:64, 0:128][1] + scene.vehicle_speed_px_per_s * (t1 - t0) >= 127.5)
    assert not flow.valid[leaving].any()
    assert flow.valid[vehicle & ~leaving].all()


def test_waving_hand_parts_are_rigid():
    scene = builtin_scene("waving-hand", height=96, width=96)
    t0, t1 = 0.02, 0.0215
    flow = scene.optical_flow_px(t0, t1)
    labels = scene.object_labels(t0)
    for part in (1, 2, 3):
        rows, cols = np.nonzero((labels == part) & flow.valid)
        if rows.size < 3:
            continue
        p = np.stack([cols, rows], 1).astype(float)
        q = p + flow.flow_px[:, rows, cols].T
        # distances between points of one part are kept (a rigid motion)
        i, j = np.random.default_rng(0).integers(0, rows.size, (2, 50))
        np.testing.assert_allclose(np.linalg.norm(q[i] - q[j], axis=1), np.linalg.norm(p[i] - p[j], axis=1),
                                   atol=1e-9)
    ratio, use = _residual_vs_contrast(scene, t0, t1, smooth_fraction=0.05)
    assert use.sum() > 100 and np.median(ratio) < 0.01


def test_night_road_depth_is_the_road_geometry():
    scene = builtin_scene("night-road-fog", height=96, width=160)
    depth = scene.depth_m(0.0)
    ifov = math.radians(20.0) / 96
    horizon = 0.42 * 96
    labels = scene.object_labels(0.0)
    row = 80
    below = row - horizon + 0.5
    road = labels[row] == 0
    np.testing.assert_allclose(depth[row, road], min(1.2 / below / ifov, 400.0), rtol=1e-12)
    assert np.isinf(depth[10]).all()  # the sky has no surface
    for obj in scene.objects(0.0):
        expected = float(obj.class_name == "car") * 80.0 or float(
            next(label for label in scene.targets if scene._target_boxes.get(label) == obj.box_xywh).split()[1])
        assert np.all(depth[labels == obj.object_id] == expected)
    flow = scene.optical_flow_px(0.0, 0.01)
    assert flow.valid.all() and not flow.flow_px.any()


def test_files_have_no_truth_and_say_so(tmp_path):
    still = StillScene(np.ones((8, 8)))
    with pytest.raises(TruthUnavailable, match="image and video files carry only light"):
        still.motion_px_per_s(0.0)
    video = VideoScene(np.ones((3, 8, 8)), 100.0)
    with pytest.raises(TruthUnavailable, match="no objects truth"):
        video.objects(0.0)
    with pytest.raises(TruthUnavailable, match="no depth truth: it gives motion, objects"):
        builtin_scene("translating", height=8, width=8).depth_m(0.0)
    assert builtin_scene("step", height=8, width=8).optical_flow_px(0, 1).valid.all()


def test_disc_fraction_inside_matches_sampling():
    rng = np.random.default_rng(3)
    for _ in range(20):
        cx, r = rng.uniform(-3, 13), rng.uniform(0.5, 4)
        ys, xs = np.mgrid[-5:5:800j, cx - r:cx + r:800j]
        disc = (xs - cx) ** 2 + ys ** 2 <= r * r
        sampled = (disc & (xs >= 0) & (xs <= 10)).sum() / disc.sum()
        assert disc_fraction_inside(cx, 0.0, r, 0.0, 10.0, -50, 50) == pytest.approx(sampled, abs=5e-3)
