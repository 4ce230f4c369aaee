"""The built-in dilemma and night-road-fog scenes: the demands they pose and their analytic truth."""

import math

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.catalog import builtin_scene
from viform.light.dilemma import DilemmaScene, NightRoadFogScene, pwm_on_time_s


def test_registered_as_builtin_scenes():
    assert isinstance(builtin_scene("dilemma", 40, 64), DilemmaScene)
    assert isinstance(builtin_scene("night-road-fog", 40, 64), NightRoadFogScene)


@pytest.mark.parametrize("shape", [(32, 48), (64, 128), (97, 151)])
def test_dilemma_poses_both_demands_at_any_size(shape):
    """≥ 6 decades in one view and motion ≥ 2 000 px/s, whatever the resolution."""
    scene = DilemmaScene(*shape)
    lux = scene.illuminance_lux(0.0123)
    assert lux.shape == shape
    assert math.log10(lux.max() / lux.min()) >= 6.0
    d = scene.demand()
    assert d["dynamic_range_db"] >= 120.0
    assert scene.prop_tip_speed_px_per_s >= 2000 and scene.vehicle_speed_px_per_s >= 2000
    assert d["time_resolution_s"] == pytest.approx(1 / d["max_speed_px_per_s"])


def test_led_is_a_90_hz_pwm_with_exact_window_mean():
    scene = DilemmaScene(32, 48)
    led = scene.led
    period = 1 / 90.0
    on, off = scene.led_on_lux, scene.led_off_lux
    assert scene.illuminance_lux(0.1 * period)[led] == pytest.approx(on)
    assert scene.illuminance_lux(0.5 * period)[led] == pytest.approx(off)
    assert scene.illuminance_lux(3.1 * period)[led] == pytest.approx(on)  # periodic
    # one whole period: the duty cycle, whatever the phase the window starts at
    for t0 in (0.0, 0.3 * period, 0.77 * period):
        mean = scene.mean_illuminance_lux(t0, t0 + period)[led]
        assert mean == pytest.approx(off + 0.25 * (on - off), rel=1e-9)
    # on-time bookkeeping: half a period from the start holds the whole on-part
    assert pwm_on_time_s(period / 2, 90.0, 0.25) == pytest.approx(0.25 * period)


def test_truth_moves_at_the_stated_speeds():
    scene = DilemmaScene(48, 96)
    dt = 2e-3
    assert scene.vehicle_front_px(dt) - scene.vehicle_front_px(0.0) == pytest.approx(2500 * dt)
    a, b = scene.illuminance_lux(0.0), scene.illuminance_lux(dt)
    static = ~(scene.moving_mask(0.0) | scene.moving_mask(dt))
    # away from the moving parts and the small object's row only the LED may change
    rows = np.abs(np.arange(48) - scene.object_row_px) > 6
    keep = static & ~scene.led & rows[:, None]
    np.testing.assert_array_equal(a[keep], b[keep])
    assert not np.array_equal(a[scene.moving_mask(0.0)], b[scene.moving_mask(0.0)])


def test_window_mean_matches_the_instantaneous_truth():
    """mean_illuminance_lux (cached grid, 0.5 px of motion a sample) agrees with a fine midpoint
    rule of illuminance_lux: the grid puts each sample within half a step (0.25 px) of the fine one,
    so the two means differ only at pixels an edge crosses, by a fraction of the edge's step."""
    scene = DilemmaScene(32, 64)
    t0, t1 = 1e-3, 4e-3
    fine = np.mean([scene.illuminance_lux(t) for t in np.linspace(t0, t1, 1201)[:-1] + (t1 - t0) / 2400], axis=0)
    mean = scene.mean_illuminance_lux(t0, t1)
    rel = np.abs(mean - fine) / fine
    assert np.median(rel) < 1e-6
    assert np.percentile(rel, 99) < 0.1


def test_brightness_and_speed_scale_the_scene():
    a, b = DilemmaScene(32, 48), DilemmaScene(32, 48, brightness=4.0, speed=2.0)
    np.testing.assert_allclose(b.illuminance_lux(0.0), 4 * a.illuminance_lux(0.0))
    assert b.max_speed_px_per_s() == 2 * a.max_speed_px_per_s()


@pytest.mark.parametrize("kw, needle", [({"height": 8}, "height"), ({"led_duty": 1.5}, "led_duty"),
                                        ({"brightness": -1}, "brightness")])
def test_bad_parameters_are_named(kw, needle):
    with pytest.raises(ViformError, match=needle):
        DilemmaScene(**{"height": 40, "width": 64, **kw})


def test_fog_hides_the_signs_from_a_passive_camera_but_not_the_range():
    """Passive contrast of a sign falls as T(R)² (Koschmieder), its range map does not change."""
    clear, fog = NightRoadFogScene(48, 96, visibility_m=2000.0), NightRoadFogScene(48, 96, visibility_m=100.0)
    mask = clear.targets["sign 60 m"]
    assert mask.any()
    assert clear.illuminance_lux(0)[mask].mean() > 5 * fog.illuminance_lux(0)[mask].mean()
    np.testing.assert_array_equal(clear.active.range_m, fog.active.range_m)
    assert np.all(clear.active.range_m[mask] == 60.0)
    assert fog.active.medium.extinction_per_m == pytest.approx(3.912 / 100.0)


@pytest.mark.parametrize("t_s", [0.012, 0.02, 0.028])
def test_every_dark_strip_is_labelled_and_the_small_object_is_pointed_at(t_s):
    """Issue 27 item 15: the figure labelled the object where nothing showed (the label box sat on
    it) and left the deep-shadow strip below the road unlabelled."""
    from scipy.ndimage import label

    scene = DilemmaScene(64, 128)
    marks = scene.landmarks(t_s)
    truth = scene.illuminance_lux(t_s)
    strips, n = label(truth <= scene.shadow_lux * 1.01)
    assert n == 2  # the road crosses the deep-shadow corner
    labelled = set()
    for where in marks.values():
        col, row = int(min(where[0], scene.width - 1)), int(min(where[1], scene.height - 1))
        labelled.add(strips[row, col])
    assert {1, 2} <= labelled
    obj = next(where for name, where in marks.items() if name.startswith("small dim object"))
    assert len(obj) == 4  # its label stands apart, with an arrow to it
    assert truth[int(round(obj[1])), int(round(obj[0]) % scene.width)] > 1.5 * truth[int(round(obj[1])), 0]
    assert abs(obj[3] - obj[1]) >= 0.05 * scene.height  # the text is off the object's row


@pytest.mark.parametrize("speed", [1.0, 0.0, 3.0])
@pytest.mark.parametrize("shape", [(64, 96), (33, 50)])
def test_rolling_rows_drawn_alone_equal_the_frames_rows(shape, speed):
    """A rolling shutter's rows (each its own window), drawn one row at a time, equal row r of the
    whole frame's mean over that row's window, bit for bit: short windows (8 samples), long ones (the
    cached grid), a zero exposure, row offsets from 0 to past the exposure; and a scene whose light a
    subclass changed takes the frame's path."""
    from viform.light.scenes import Scene

    rng = np.random.default_rng(5)
    for exposure_s in (0.0, 2e-5, 1e-4, 5e-3):
        for row_offset_s in (0.0, 1e-6, 1.3e-4):
            scene = DilemmaScene(*shape, speed=speed)
            t0 = float(rng.uniform(0, 0.04))
            framed = Scene.rolling_mean_illuminance_lux(scene, t0, exposure_s, row_offset_s)
            assert np.array_equal(scene.rolling_mean_illuminance_lux(t0, exposure_s, row_offset_s), framed)

    class Brighter(DilemmaScene):
        def illuminance_lux(self, t_s):
            return 2 * super().illuminance_lux(t_s)

        def mean_illuminance_lux(self, t0_s, t1_s, samples=None):
            return 2 * super().mean_illuminance_lux(t0_s, t1_s, samples)

    brighter = Brighter(*shape, speed=speed)
    assert np.array_equal(brighter.rolling_mean_illuminance_lux(0.01, 1e-4, 1e-6),
                          2 * DilemmaScene(*shape, speed=speed).rolling_mean_illuminance_lux(0.01, 1e-4, 1e-6))
