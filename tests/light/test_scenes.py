"""Scenes: analytic ground truth, exact window means, explicit pixel → lux mapping."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.catalog import builtin_scene, load_scene
from viform.light.scenes import (
    FlickerScene,
    HDRScene,
    RotatingScene,
    StepScene,
    StillScene,
    TranslatingScene,
    VideoScene,
    image_to_lux,
)


def test_translating_pattern_moves_at_its_speed():
    scene = TranslatingScene(32, 64, velocity_px_per_s=(1000.0, 0.0), pattern="bars", period_px=16)
    a = scene.illuminance_lux(0.0)
    b = scene.illuminance_lux(0.004)  # 4 px later
    assert np.array_equal(b[:, 4:], a[:, :-4])


def test_rotating_pattern_returns_after_a_turn():
    scene = RotatingScene(33, 33, angular_speed_rad_per_s=2 * np.pi * 10)
    # after a whole turn only the centre row and column, on a checker edge, may differ (rounding)
    assert np.mean(~np.isclose(scene.illuminance_lux(0.0), scene.illuminance_lux(0.1))) < 0.07
    assert np.mean(~np.isclose(scene.illuminance_lux(0.0), scene.illuminance_lux(0.0125))) > 0.3


def test_hdr_scene_spans_six_decades():
    scene = HDRScene(20, 200, min_lux=0.01, decades=6)
    lux = scene.illuminance_lux(0.0)
    assert lux.max() / lux.min() >= 1e6 * 0.999


def test_step_scene_window_mean_is_exact():
    scene = StepScene(step_time_s=0.01, factor=10.0, height=4, width=4, lux=2.0)
    mean = scene.mean_illuminance_lux(0.005, 0.015)
    assert np.allclose(mean, 2.0 * 0.5 + 20.0 * 0.5)
    assert np.allclose(scene.illuminance_lux(0.0099), 2.0)
    assert np.allclose(scene.illuminance_lux(0.01), 20.0)


@pytest.mark.parametrize("waveform", ["sine", "square"])
def test_flicker_mean_over_whole_periods_is_the_base(waveform):
    scene = FlickerScene(frequency_hz=100.0, depth=0.8, waveform=waveform, height=2, width=2, lux=3.0)
    assert np.allclose(scene.mean_illuminance_lux(0.0013, 0.0013 + 0.03), 3.0)
    # exact mean agrees with a fine midpoint rule over a partial period
    numeric = np.mean([scene.illuminance_lux(t)[0, 0] for t in np.linspace(0.001, 0.004, 30001)[:-1] + 5e-8])
    assert scene.mean_illuminance_lux(0.001, 0.004)[0, 0] == pytest.approx(numeric, rel=2e-3)


def test_video_hold_and_linear_interpolation():
    frames = np.stack([np.full((2, 3), 1.0), np.full((2, 3), 3.0)])
    hold = VideoScene(frames, frame_rate_hz=100.0, interpolation="hold")
    linear = VideoScene(frames, frame_rate_hz=100.0, interpolation="linear")
    assert np.allclose(hold.illuminance_lux(0.005), 1.0)
    assert np.allclose(linear.illuminance_lux(0.005), 2.0)
    assert np.allclose(linear.illuminance_lux(1.0), 3.0)  # past the end: last frame held


def test_integer_images_map_linearly_to_max_lux():
    image = np.array([[0, 255]], dtype=np.uint8)
    assert np.allclose(image_to_lux(image, 500.0), [[0.0, 500.0]])
    assert np.allclose(image_to_lux(np.array([[0.5]]), None), [[0.5]])  # float: lux already
    with pytest.raises(ViformError, match="max_lux"):
        image_to_lux(image, None)


def test_still_scene_refuses_nan_and_negative_lux():
    with pytest.raises(ViformError, match="NaN"):
        StillScene(np.array([[1.0, np.nan]]))
    with pytest.raises(ViformError, match="negative"):
        StillScene(np.array([[1.0, -2.0]]))


def test_image_and_video_files_load(tmp_path):
    import imageio.v3 as iio

    image = (np.arange(12, dtype=np.uint8).reshape(3, 4) * 20)
    iio.imwrite(tmp_path / "a.png", image)
    still = load_scene(str(tmp_path / "a.png"), max_lux=255.0)
    assert np.allclose(still.illuminance_lux(0.0), image)
    folder = tmp_path / "seq"
    folder.mkdir()
    for i in range(3):
        iio.imwrite(folder / f"{i:02d}.png", np.full((3, 4), 50 * i, np.uint8))
    video = load_scene(str(folder), max_lux=255.0, frame_rate_hz=10.0, interpolation="hold")
    assert np.allclose(video.illuminance_lux(0.15), 50.0)


def test_unreadable_video_and_unknown_scene_give_clear_errors(tmp_path):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video")
    with pytest.raises(ViformError, match="could not be read"):
        load_scene(str(bad), frame_rate_hz=30.0)
    with pytest.raises(ViformError, match="neither a built-in scene"):
        load_scene("no-such-scene")


def test_mp4_video_declares_its_frame_rate(tmp_path):
    """A real video file (imageio-ffmpeg): the declared 25 fps is used, pixel values map to lux."""
    import imageio.v3 as iio

    frames = np.stack([np.full((16, 32), 40 * i, np.uint8) for i in range(5)])
    iio.imwrite(tmp_path / "v.mp4", frames, fps=25, codec="libx264")
    video = load_scene(str(tmp_path / "v.mp4"), max_lux=255.0, interpolation="hold")
    assert video.frame_rate_hz == pytest.approx(25.0)
    assert video.shape == (16, 32)
    # lossy codec: compare the frame means with a few grey levels of slack
    assert np.mean(video.illuminance_lux(0.0)) == pytest.approx(0.0, abs=4)
    assert np.mean(video.illuminance_lux(0.13)) == pytest.approx(120.0, abs=4)  # frame 3


CORE_SCENES = ("translating", "moving-edge", "rotating", "hdr", "step", "flicker")


def _compiled_scenes():
    rng = np.random.default_rng(0)
    frames = rng.uniform(0.0, 3.0, (5, 12, 20))
    pattern = TranslatingScene(12, 20, velocity_px_per_s=(900.0, -300.0), period_px=6.0)
    return {
        **{name: builtin_scene(name, 12, 20) for name in CORE_SCENES},
        "video-hold": VideoScene(frames, 300.0, "hold"),
        "video-linear": VideoScene(frames, 300.0, "linear"),
        "bars-rotating": RotatingScene(12, 20, pattern="bars", period_px=5.0),
        "step-pattern": StepScene(pattern, step_time_s=0.004, factor=3.0),
        "square-flicker-pattern": FlickerScene(pattern, frequency_hz=450.0, depth=0.5, waveform="square"),
    }


@pytest.mark.parametrize("name", ["translating", "moving-edge", "rotating", "hdr", "step", "flicker", "video-hold",
                                  "video-linear", "bars-rotating", "step-pattern", "square-flicker-pattern"])
def test_compiled_light_is_the_scene_light(name):
    """What the kernel evaluates equals the NumPy scene to rounding (a few ulps of the
    angle-addition gratings; 2e-7 leaves room); patterns may differ only exactly on a
    discontinuity (no pixel here)."""
    from viform.light.compiled import evaluate

    scene = _compiled_scenes()[name]
    light = scene.compiled_light()
    assert light is not None
    times = np.array([0.0, 1.3e-4, 2.1e-3, 4.0e-3, 4.2e-3, 7.77e-3, 0.02])
    expected = scene.illuminance_lux_many(times)
    got = evaluate(light, times)
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=2e-7, atol=1e-12)


def test_scenes_that_change_their_light_fall_back_to_numpy():
    """A subclass overriding the light (or an arbitrary Scene) has no compiled form."""

    class Brighter(StillScene):
        def illuminance_lux(self, t_s):
            return 2 * super().illuminance_lux(t_s)

    class Wobbly(TranslatingScene):
        def illuminance_lux(self, t_s):
            return super().illuminance_lux(t_s) * (1 + 0.1 * np.sin(t_s))

    assert Brighter(np.ones((2, 2))).compiled_light() is None
    assert Wobbly(4, 4).compiled_light() is None
    assert StillScene(np.ones((2, 2))).compiled_light() is not None


def _rows_of_window_means(scene, t0_s, exposure_s, row_offset_s):
    """Row r of the whole frame's mean over row r's own window: what a rolling shutter's rows are."""
    return np.stack([scene.mean_illuminance_lux(t0_s + r * row_offset_s, t0_s + r * row_offset_s + exposure_s)[r]
                     for r in range(scene.height)])


@pytest.mark.parametrize("shape", [(33, 50), (7, 129)])
@pytest.mark.parametrize("make", [
    lambda h, w: TranslatingScene(h, w, velocity_px_per_s=(2300.0, -700.0)),
    lambda h, w: TranslatingScene(h, w, pattern="edge"),
    lambda h, w: TranslatingScene(h, w, pattern="bars", velocity_px_per_s=(0.0, 900.0), origin_px=(3.3, 1.1)),
    lambda h, w: RotatingScene(h, w, angular_speed_rad_per_s=-70.0),
    lambda h, w: builtin_scene("waving-hand", max(h, 16), max(w, 16), wave_hz=40.0),
], ids=["texture", "edge", "bars", "rotating", "waving-hand"])
def test_rolling_rows_drawn_at_once_equal_each_rows_window_mean(make, shape):
    """A rolling shutter's rows, each sample drawn for every row at once at the row's own instant, equal row r
    of the whole frame's mean over row r's window, bit for bit: zero, short and long exposures, row offsets
    from 0 to past the exposure, windows starting anywhere."""
    scene = make(*shape)
    shape = scene.shape
    rng = np.random.default_rng(3)
    for exposure_s in (0.0, 2e-5, 1e-4, 5e-3):
        for row_offset_s in (0.0, 1e-6, 1.3e-4, -7e-5):
            t0 = float(rng.uniform(0.0, 0.04))
            rows = scene.rolling_mean_illuminance_lux(t0, exposure_s, row_offset_s)
            assert np.array_equal(rows, _rows_of_window_means(scene, t0, exposure_s, row_offset_s))
    # a window that has length in row 0 only (1e-19 s vanishes beside 1 ms): rows of both kinds in one exposure
    rows = scene.rolling_mean_illuminance_lux(0.0, 1e-19, 1e-3)
    assert np.array_equal(rows, _rows_of_window_means(scene, 0.0, 1e-19, 1e-3))
    times = rng.uniform(0.0, 0.04, shape[0])
    assert np.array_equal(scene.illuminance_lux_row_times(times),
                          np.stack([scene.illuminance_lux(float(t))[r] for r, t in enumerate(times)]))


def test_rolling_rows_of_a_scene_whose_light_a_subclass_changed_and_bad_windows():
    """A subclass that changes the light gets its own light's rows (drawn frame by frame); a window that ends
    before it starts is refused, naming it; a row-times array of the wrong length is refused."""
    class Brighter(TranslatingScene):
        def illuminance_lux(self, t_s):
            return 2.0 * super().illuminance_lux(t_s)

    brighter = Brighter(21, 30)
    rows = brighter.rolling_mean_illuminance_lux(0.004, 3e-4, 2e-5)
    assert np.array_equal(rows, _rows_of_window_means(brighter, 0.004, 3e-4, 2e-5))
    assert np.allclose(rows, 2.0 * TranslatingScene(21, 30).rolling_mean_illuminance_lux(0.004, 3e-4, 2e-5),
                       rtol=1e-12)
    for exposure_s in (-1e-4, float("nan")):
        with pytest.raises(ViformError, match="window end t1_s="):
            TranslatingScene(8, 8).rolling_mean_illuminance_lux(0.001, exposure_s, 1e-5)
    for scene in (TranslatingScene(8, 8), Brighter(8, 8)):
        with pytest.raises(ViformError, match="8 are needed, one per row"):
            scene.illuminance_lux_row_times(np.zeros(7))


def test_light_patched_on_one_scene_is_what_its_exposures_see():
    """A scene whose light (or mean) is replaced on the scene itself, not its class, integrates that light:
    its window means and rolling rows are the frame-by-frame ones of the patched light, and it is not
    compiled."""
    patched = TranslatingScene(12, 20)
    patched.illuminance_lux = lambda t_s: np.full((12, 20), 3.0 + 1000.0 * t_s)
    assert patched.compiled_light() is None
    rows = patched.rolling_mean_illuminance_lux(0.002, 1e-3, 1e-4)
    assert np.array_equal(rows, _rows_of_window_means(patched, 0.002, 1e-3, 1e-4))
    assert np.allclose(rows[:, 0], 3.0 + 1000.0 * (0.002 + np.arange(12) * 1e-4 + 0.5e-3))
    meaned = TranslatingScene(12, 20)
    meaned.mean_illuminance_lux = lambda t0_s, t1_s, samples=32: np.full((12, 20), t0_s)
    assert np.array_equal(meaned.rolling_mean_illuminance_lux(0.002, 1e-3, 1e-4)[:, 0], 0.002 + np.arange(12) * 1e-4)
