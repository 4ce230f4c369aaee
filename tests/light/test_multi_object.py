"""The multi-object tracking scene: exact boxes, velocities, visibility and flow."""

import math

import numpy as np
import pytest

from viform.light.catalog import builtin_scene
from viform.light.multi_object import MultiObjectScene


@pytest.fixture(scope="module")
def scene():
    return builtin_scene("multi-object", height=64, width=96)


def test_registered_and_spans_the_brief():
    s = builtin_scene("multi-object")
    assert s.name == "multi-object" and set(s.truth_kinds()) == {"motion", "objects"}
    speeds = [math.hypot(*s.velocity_px_per_s(spec, 0.01)) for spec in s.specs]
    assert len(s.specs) >= 5 and min(speeds) == pytest.approx(100) and max(speeds) == pytest.approx(10_000)
    assert min(spec.lux for spec in s.specs) <= 1.0
    sizes = {spec.size_px for spec in s.specs}
    assert len(sizes) == len(s.specs)


def test_boxes_match_rendered_masks(scene):
    # an object rendered alone: the pixels its light touches are exactly those its box overlaps
    for t in (0.0, 0.011, 0.025, 0.04):
        labels = scene.object_labels(t)
        for obj in scene.objects(t):
            spec = scene.specs[obj.object_id - 1]
            alone = MultiObjectScene(64, 96, background="plain")
            alone._paint_order = [spec]
            touched = alone.illuminance_lux(t) != alone.background_lux
            x0, y0, w, h = obj.box_xywh
            cols = np.arange(96)
            rows = np.arange(64)
            overlaps_x = (cols + 1 > x0) & (cols < x0 + w)
            overlaps_y = (rows + 1 > y0) & (rows < y0 + h)
            np.testing.assert_array_equal(touched, np.outer(overlaps_y, overlaps_x))
            # labels: the centre rule, minus what nearer objects hide
            centre_in = np.outer((rows + 0.5 >= y0) & (rows + 0.5 < y0 + h), (cols + 0.5 >= x0) & (cols + 0.5 < x0 + w))
            assert not np.any((labels == obj.object_id) & ~centre_in)
            if obj.visible_fraction == 1.0:
                np.testing.assert_array_equal(labels == obj.object_id, centre_in)


def test_velocity_is_the_derivative_of_the_box(scene):
    h = 1e-6
    for t in (0.003, 0.02, 0.037):
        before = {o.object_id: o for o in scene.objects(t - h)}
        after = {o.object_id: o for o in scene.objects(t + h)}
        for obj in scene.objects(t):
            a, b = before[obj.object_id], after[obj.object_id]
            fd = ((b.x_px + b.width_px / 2 - a.x_px - a.width_px / 2) / (2 * h),
                  (b.y_px + b.height_px / 2 - a.y_px - a.height_px / 2) / (2 * h))
            np.testing.assert_allclose(fd, obj.velocity_px_per_s, rtol=1e-6, atol=1e-3)
    # the drone turns: its velocity changes direction over the clip
    drone = [[o for o in scene.objects(t) if o.class_name == "drone"][0].velocity_px_per_s for t in (0.0, 0.05)]
    assert np.dot(drone[0], drone[1]) < 0.95 * np.linalg.norm(drone[0]) * np.linalg.norm(drone[1])


def test_full_occlusion_visible_fraction(scene):
    def ball(t):
        return [o for o in scene.objects(t) if o.class_name == "ball"][0].visible_fraction

    ts = np.linspace(0.0, 0.05, 201)
    frac = np.array([ball(t) for t in ts])
    assert frac[0] == 1.0 and frac[-1] == 1.0
    assert ball(scene.t_ref_s) == 0.0
    hidden = ts[frac == 0.0]
    # fully hidden while the 16-px ball is inside the 44-px truck: |Δx| ≤ 14 px at 3,000 px/s (reference size)
    assert hidden.min() == pytest.approx(0.025 - 14 / 3000, abs=3e-4)
    assert hidden.max() == pytest.approx(0.025 + 14 / 3000, abs=3e-4)
    # the label image agrees: no pixel of the ball at t_ref
    assert not np.any(scene.object_labels(scene.t_ref_s) == 2)
    # visible fraction against the pixel count of its label (1-px rounding at the edges)
    for t in (0.019, 0.031):
        obj = [o for o in scene.objects(t) if o.class_name == "ball"][0]
        count = np.count_nonzero(scene.object_labels(t) == 2)
        assert count == pytest.approx(obj.visible_fraction * obj.width_px * obj.height_px, abs=obj.height_px + 1)


def test_enters_and_leaves(scene):
    ids = [{o.object_id for o in scene.objects(t)} for t in (0.0, 0.025, 0.049)]
    assert 3 not in ids[0] and 3 in ids[1]  # the bullet enters
    assert 4 in ids[0] and 4 not in ids[2]  # the car leaves


def test_flow_is_displacement_and_marks_occlusion(scene):
    flow = scene.optical_flow_px(0.02, 0.021)
    labels = scene.object_labels(0.02)
    assert np.all(flow.flow_px[:, labels == 0] == 0)
    truck = [o for o in scene.objects(0.02) if o.class_name == "truck"][0]
    np.testing.assert_allclose(flow.flow_px[:, labels == 1].mean(axis=1), np.array(truck.velocity_px_per_s) * 1e-3)
    # the ball slides under the truck: its pixels that land under the truck are invalid
    early = scene.optical_flow_px(0.018, 0.019)
    ball = scene.object_labels(0.018) == 2
    assert np.any(~early.valid[ball]) and np.any(early.valid[ball])
    # background uncovered later is valid; background covered at t1 is not
    assert np.all(~flow.valid[(labels == 0) & (scene.object_labels(0.021) != 0)])
    motion = scene.motion_px_per_s(0.02)
    np.testing.assert_allclose(motion[:, labels == 1].T, np.tile(truck.velocity_px_per_s, (np.sum(labels == 1), 1)))


def test_brightness_and_speed_factors():
    dim = MultiObjectScene(64, 96, brightness=0.01, speed=4.0)
    ref = MultiObjectScene(64, 96)
    spec = ref.specs[0]
    assert dim.object_lux(spec) == pytest.approx(0.01 * ref.object_lux(spec))
    assert dim.velocity_px_per_s(spec, 0.0)[0] == pytest.approx(4 * ref.velocity_px_per_s(spec, 0.0)[0])
    assert dim.objects(dim.t_ref_s)[1].visible_fraction == 0.0  # the crossing stays at t_ref
    with pytest.raises(Exception, match="brightness"):
        MultiObjectScene(64, 96, brightness=-1)
