"""Described scenes: exact coverage, truth that moves the light, and the built-in scenes' descriptions."""

import numpy as np
import pytest

from viform.light.catalog import builtin_scene, described_scene
from viform.light.description import load_description
from viform.light.layered import DescribedScene, polygon_coverage
from viform.sensors.spike import SpikeSensor


def _scene(layers, width=48, height=32, camera=None, background=None):
    doc = {"viform_scene": 1, "name": "t", "canvas": {"width_px": width, "height_px": height},
           "background": background or {"source": {"pattern": {"name": "texture", "period_px": 12.0,
                                                               "lux": [2.0, 6.0]}}, "depth_m": 50.0},
           "layers": layers}
    if camera:
        doc["camera"] = camera
    return DescribedScene(load_description(doc))


def test_polygon_coverage_is_the_exact_area():
    rng = np.random.default_rng(0)
    for _ in range(20):  # random triangles and a concave polygon: total coverage = area
        pts = rng.uniform(1, 15, (3, 2))
        cov = polygon_coverage(pts[:, 0], pts[:, 1], 0, 0, 16, 16)
        (ax, ay), (bx, by) = pts[1] - pts[0], pts[2] - pts[0]
        area = 0.5 * abs(ax * by - ay * bx)
        assert cov.sum() == pytest.approx(area, rel=1e-12, abs=1e-12)
        assert cov.min() >= -1e-12 and cov.max() <= 1 + 1e-12
    x = np.array([2.0, 12.0, 12.0, 7.0, 2.0])
    y = np.array([2.0, 2.0, 12.0, 5.5, 12.0])  # an arrow head: concave
    cov = polygon_coverage(x, y, 0, 0, 16, 16)
    assert cov.sum() == pytest.approx(100 - 0.5 * 10 * 6.5, rel=1e-12)
    # a pixel cut by a 45° line through its corners is half covered
    assert polygon_coverage(np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), 0, 0, 1, 1)[0, 0] == \
        pytest.approx(0.5)


def test_whole_pixel_moves_reproduce_the_light_and_rigid_layers_stay_rigid():
    layer = {"source": {"pattern": {"name": "noise", "period_px": 5.0, "lux": [10.0, 40.0]}},
             "shape": {"polygon": {"points_px": [[-6, -5], [7, -4], [3, 6], [-5, 4]]}},
             "position_px": [14.0, 15.0], "depth_m": 5.0, "object": {"id": 1, "class": "thing"},
             "motion": {"velocity": {"px_per_s": [1000.0, -500.0]}}}
    scene = _scene([layer])
    t0, t1 = 0.002, 0.006  # +4 px, −2 px: whole pixels
    a, b = scene.illuminance_lux(t0), scene.illuminance_lux(t1)
    flow = scene.optical_flow_px(t0, t1)
    labels = scene.object_labels(t0)
    inside = flow.valid & (labels == 1)
    rows, cols = np.nonzero(inside)
    assert inside.sum() > 50
    np.testing.assert_allclose(flow.flow_px[0][inside], 4.0, atol=1e-9)
    np.testing.assert_allclose(flow.flow_px[1][inside], -2.0, atol=1e-9)
    np.testing.assert_allclose(b[rows - 2, cols + 4], a[rows, cols], rtol=1e-12)
    # the background is still: its valid pixels keep their light (where no layer edge crosses them at t1)
    labels1, mixed1 = scene._labels_and_mixed(t1)
    still = flow.valid & (labels == 0) & (labels1 == 0) & ~mixed1
    np.testing.assert_allclose(b[still], a[still], rtol=1e-12)
    obj = scene.objects(t0)[0]
    assert obj.velocity_px_per_s == pytest.approx((1000.0, -500.0), rel=1e-6)
    depth = scene.depth_m(t0)
    assert set(np.unique(depth)) == {5.0, 50.0}


def test_brightness_constancy_residual_of_a_rotating_layer_is_small():
    layer = {"source": {"pattern": {"name": "noise", "period_px": 24.0, "lux": [10.0, 40.0]}},
             "shape": {"ellipse": {"width_px": 24, "height_px": 18}}, "position_px": [24.0, 16.0],
             "depth_m": 5.0, "motion": {"velocity": {"rad_per_s": 20.0}}}
    scene = _scene([layer], width=48, height=32)
    t0, dt = 0.01, 0.002  # 0.04 rad: ≤ 0.5 px at the rim
    a, b = scene.illuminance_lux(t0), scene.illuminance_lux(t0 + dt)
    flow = scene.optical_flow_px(t0, t0 + dt)
    y, x = np.mgrid[0:32, 0:48].astype(float)
    from scipy.ndimage import map_coordinates

    warped = map_coordinates(b, [y + flow.flow_px[1], x + flow.flow_px[0]], order=1, mode="nearest")
    from scipy.ndimage import binary_erosion

    inner = flow.valid & binary_erosion(scene.layer_labels(t0) == 1, iterations=2)  # interpolation stays inside
    residual = np.abs(warped - a)[inner].mean()
    plain = np.abs(b - a)[inner].mean()
    assert residual < 0.2 * plain  # the truth explains most of the change (interpolation error remains)


def test_camera_pan_moves_everything_and_leaving_pixels_are_invalid():
    scene = _scene([], camera={"motion": {"velocity": {"px_per_s": [2000.0, 0.0]}}})
    flow = scene.optical_flow_px(0.0, 0.002)  # +4 px
    np.testing.assert_allclose(flow.flow_px[0], 4.0, atol=1e-9)
    assert not flow.valid[:, -4:].any() and flow.valid[:, :-4].all()


@pytest.mark.parametrize("name", ["translating", "moving-edge", "rotating", "step", "flicker", "multi-object"])
def test_shipped_descriptions_give_the_builtin_scenes_bits(name):
    """Each shipped description renders its built-in scene's light (rounding apart) at the description's
    size, so the spikes are the same bits; and the truth is the same."""
    described = described_scene(name)
    coded = builtin_scene(name, *described.shape)
    for t in (0.0, 0.0123):
        np.testing.assert_allclose(described.illuminance_lux(t), coded.illuminance_lux(t), rtol=1e-13)
    sensor = SpikeSensor(threshold_electrons=300 if name == "multi-object" else 30, gain_spread_fraction=0.05)
    ticks = 40 if name == "multi-object" else 100
    a = sensor.capture(described, ticks / 40e3, seed=3, light_sample_ticks=1).spikes
    b = sensor.capture(coded, ticks / 40e3, seed=3, light_sample_ticks=1).spikes
    assert 0.01 < a.mean() < 0.9 and np.array_equal(a, b)
    np.testing.assert_array_equal(described.object_labels(0.0123), coded.object_labels(0.0123))
    d_objects = {o.object_id: o for o in described.objects(0.0123)}
    for o in coded.objects(0.0123):
        assert d_objects[o.object_id].box_xywh == pytest.approx(o.box_xywh, abs=1e-9)
        assert d_objects[o.object_id].visible_fraction == pytest.approx(o.visible_fraction, abs=1e-9)
    fd, fc = described.optical_flow_px(0.01, 0.011), coded.optical_flow_px(0.01, 0.011)
    both = fd.valid & fc.valid
    np.testing.assert_allclose(fd.flow_px[:, both], fc.flow_px[:, both], atol=1e-9)
    assert (fd.valid == fc.valid).mean() > 0.99  # the description also marks mixed edge pixels invalid


def _clip_textbook(subject, clip):
    """Sutherland–Hodgman written point by point (the reference for the compiled clip)."""
    from viform.light.layered import _ccw

    sx, sy = [float(v) for v in subject[0]], [float(v) for v in subject[1]]
    cx, cy = _ccw(np.asarray(clip[0], float), np.asarray(clip[1], float))
    n = len(cx)
    for k in range(n):
        if not sx:
            break
        ax, ay, bx, by = float(cx[k]), float(cy[k]), float(cx[(k + 1) % n]), float(cy[(k + 1) % n])
        ox, oy = [], []
        for i in range(len(sx)):
            px_, py_, qx, qy = sx[i - 1], sy[i - 1], sx[i], sy[i]
            sp = (bx - ax) * (py_ - ay) - (by - ay) * (px_ - ax)
            sq = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
            if sq >= 0:
                if sp < 0:
                    w = sp / (sp - sq)
                    ox.append(px_ + w * (qx - px_))
                    oy.append(py_ + w * (qy - py_))
                ox.append(qx)
                oy.append(qy)
            elif sp >= 0:
                w = sp / (sp - sq)
                ox.append(px_ + w * (qx - px_))
                oy.append(py_ + w * (qy - py_))
        sx, sy = ox, oy
    return np.array(sx, float), np.array(sy, float)


def test_clip_convex_is_the_textbook_clip_and_its_areas_are_right():
    """The compiled clip gives the point-by-point Sutherland–Hodgman's vertices to the bit (convex and star
    subjects, clips either way round, meeting, containing, disjoint); and the areas of known overlaps."""
    from viform.light.layered import clip_convex, ellipse_polygon, polygon_area

    rng = np.random.default_rng(7)
    for case in range(400):
        sides = int(rng.integers(3, 40))
        subject = ellipse_polygon(*rng.uniform(2, 30, 2), *rng.uniform(-10, 10, 2), sides=sides)
        if case % 3 == 0:  # a star: not convex
            r = np.where(np.arange(sides) % 2 == 0, 1.0, 0.4)
            subject = (subject[0] * r, subject[1] * r)
        clip = ellipse_polygon(*rng.uniform(2, 30, 2), *rng.uniform(-10, 10, 2), sides=int(rng.integers(3, 30)))
        if case % 2:
            clip = (clip[0][::-1], clip[1][::-1])  # clockwise
        got, want = clip_convex(subject, clip), _clip_textbook(subject, clip)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    square = (np.array([0.0, 1.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0, 1.0]))
    for bad in (np.nan, np.inf):  # a vertex that is not finite: the same points as the textbook's tests give
        subject = (np.array([0.2, 0.8, bad, 0.2]), np.array([0.2, 0.2, 0.5, 0.8]))
        got, want = clip_convex(subject, square), _clip_textbook(subject, square)
        assert np.array_equal(got[0], want[0], equal_nan=True) and np.array_equal(got[1], want[1], equal_nan=True)
    assert polygon_area(*clip_convex(square, (square[0] + 0.5, square[1] + 0.25))) == pytest.approx(0.375)
    inner = (0.25 + 0.5 * square[0], 0.25 + 0.5 * square[1])
    assert polygon_area(*clip_convex(inner, square)) == pytest.approx(0.25)
    assert clip_convex(square, (square[0] + 3.0, square[1]))[0].size == 0
