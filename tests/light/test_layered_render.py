"""The described scenes' compiled renderer: the light of the NumPy reference, whatever the work split, and the
NumPy light path's spike bits through the sampled driver."""

import numpy as np
import pytest

import viform.light.layered_render as layered_render
from viform.light.description import load_description
from viform.light.layered import DescribedScene
from viform.sensors.spike import SpikeSensor

HEIGHT, WIDTH = 40, 64


def _scene(tmp_path) -> DescribedScene:
    """Every path of the renderer: axis-aligned images magnified (per-column tables) and minified (summed-area
    table), a growing image, a rotating image, an image with an alpha channel, sines translating (table) and
    rotating, a flickering glow added on top; over a static image background."""
    rng = np.random.default_rng(5)

    def npy(name, shape, alpha=False):
        values = rng.uniform(0.5, 4.0, shape)
        if alpha:
            values = np.stack([values, rng.uniform(0.0, 1.0, shape)], axis=-1)
        path = tmp_path / f"{name}.npy"
        np.save(path, values)
        return str(path)

    def image(name, shape, size, alpha=False):
        return {"image": {"path": npy(name, shape, alpha), "size_px": list(size)}}

    doc = {
        "viform_scene": 1, "name": "render-paths", "canvas": {"width_px": WIDTH, "height_px": HEIGHT},
        "background": {"source": image("bg", (30, 50), (WIDTH, HEIGHT)), "position_px": [32.0, 20.0]},
        "layers": [
            {"source": image("magnified", (9, 13), (26.0, 17.0)), "position_px": [14.3, 11.7],
             "motion": {"velocity": {"px_per_s": [900.0, 350.0]}}},
            {"source": image("minified", (60, 84), (21.0, 15.0)), "position_px": [48.2, 28.9],
             "motion": {"velocity": {"px_per_s": [-640.0, 210.0]}}},
            {"source": image("growing", (11, 17), (17.0, 11.0)), "position_px": [30.6, 8.4],
             "motion": {"velocity": {"px_per_s": [120.0, 400.0], "scale_per_s": 9.0}},
             "shape": {"ellipse": {"width_px": 15.0, "height_px": 10.0}}},
            {"source": image("rotating", (14, 20), (20.0, 14.0)), "position_px": [20.5, 30.1],
             "motion": {"velocity": {"px_per_s": [300.0, -100.0], "rad_per_s": 25.0}}},
            {"source": image("alpha", (10, 12, ), (18.0, 15.0), alpha=True), "shape": {"alpha": {}},
             "position_px": [44.1, 12.2], "motion": {"velocity": {"px_per_s": [-200.0, 500.0]}}},
            {"source": {"pattern": {"name": "sines", "period_px": 5.3, "lux": 3.0, "depth": 0.6}},
             "shape": {"rectangle": {"width_px": 14.0, "height_px": 9.0}}, "position_px": [8.9, 31.3],
             "motion": {"velocity": {"px_per_s": [700.0, -60.0]}}},
            {"source": {"pattern": {"name": "sines", "period_px": 4.1, "lux": 2.0}},
             "shape": {"polygon": {"points_px": [[-6, -5], [7, -4], [5, 6], [-4, 5]]}}, "position_px": [54.0, 33.0],
             "motion": {"velocity": {"px_per_s": [-100.0, -300.0], "rad_per_s": -14.0}}},
            {"source": {"gaussian": {"lux": 5.0, "sigma_px": 4.0}}, "blend": "add", "position_px": [36.0, 22.0],
             "shape": {"ellipse": {"width_px": 20.0, "height_px": 20.0}},
             "modulation": {"sine": {"frequency_hz": 900.0, "depth": 0.8}}},
        ],
    }
    return DescribedScene(load_description(doc))


TIMES = (np.array([0, 7, 131, 402, 777, 1203]) + 0.5) / 40e3


def test_renderer_is_the_numpy_reference(tmp_path):
    """Every instant, every pixel: the compiled light equals :meth:`DescribedScene.reference_lux` to rounding."""
    scene = _scene(tmp_path)
    got = scene.sampler().frames(TIMES)
    for frame, t in zip(got, TIMES, strict=True):
        ref = scene.reference_lux(t)
        assert ref.min() > 0.1
        np.testing.assert_allclose(frame, ref, rtol=1e-12, atol=0)
    # the layers moved: the light differs between instants
    assert np.abs(got[0] - got[-1]).max() > 0.5


@pytest.mark.parametrize("parallel_work", [0, 1 << 62])
def test_renderer_bits_do_not_depend_on_the_work_split(tmp_path, monkeypatch, parallel_work):
    """One thread or many, per sample or per group of rows, whole field or a few ranges: the same bits."""
    scene = _scene(tmp_path)
    reference = np.stack([scene.sampler().frames(TIMES[k:k + 1])[0] for k in range(TIMES.size)])
    monkeypatch.setattr(layered_render, "PARALLEL_WORK", parallel_work)
    sampler = layered_render.LayeredSampler(scene)
    assert np.array_equal(sampler.frames(TIMES), reference)
    assert np.array_equal(sampler.frames(TIMES[2:3])[0], reference[2])
    # a few flat ranges (rows cut mid-way), as the simulator asks for its dirty words
    starts = np.array([3, 5 * WIDTH + 17, 20 * WIDTH + 40], np.int64)
    stops = np.array([WIDTH + 9, 9 * WIDTH + 2, 31 * WIDTH + 5], np.int64)
    pixels = int((stops - starts).sum())
    out = np.empty((TIMES.size, pixels))
    one = np.ones(pixels)
    sampler.render(TIMES, starts, stops, one, one, out)
    flat = reference.reshape(TIMES.size, -1)
    expected = np.concatenate([flat[:, s:e] for s, e in zip(starts, stops, strict=True)], axis=1)
    assert np.array_equal(out, expected)


@pytest.mark.parametrize("sample_ticks", [1, 4])
def test_sampled_driver_gives_the_numpy_path_bits(tmp_path, sample_ticks):
    """The static words as one run and the dirty ones per light sample: the bits of the NumPy per-tick path."""
    scene = _scene(tmp_path)
    assert scene.compiled_light().kind == "sampled"
    sensor = SpikeSensor(threshold_electrons=40, gain_spread_fraction=0.05, dark_current_spread_fraction=0.3)
    duration = 300 / 40e3
    fast = sensor.capture(scene, duration, seed=9, block_ticks=97, light_sample_ticks=sample_ticks).spikes
    numpy_path = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=9, block_ticks=300,
                                                               light_sample_ticks=sample_ticks,
                                                               compiled_light=False)])
    assert 0.01 < fast.mean() < 0.9
    assert np.array_equal(fast, numpy_path)


def _rows_of_window_means(scene, t0_s, exposure_s, row_offset_s):
    """Row r of the whole field's mean over row r's own window: what a rolling shutter's rows are."""
    return np.stack([scene.mean_illuminance_lux(t0_s + r * row_offset_s, t0_s + r * row_offset_s + exposure_s)[r]
                     for r in range(scene.height)])


def test_rolling_rows_rendered_each_at_its_instant_are_the_fields_rows(tmp_path):
    """A rolling shutter's rows, every row rendered once per sample at its own instant, equal row r of the
    whole field's mean over row r's window, bit for bit, on every path of the renderer (moving, growing,
    rotating and flickering layers): zero, short and long exposures, row offsets from 0 to past the exposure,
    one and two threads."""
    from numba import get_num_threads, set_num_threads

    scene = _scene(tmp_path)
    rng = np.random.default_rng(11)
    threads = get_num_threads()
    try:
        for n_threads in sorted({1, threads}):
            set_num_threads(n_threads)
            for exposure_s in (0.0, 3e-5, 1e-3, 8e-3):
                for row_offset_s in (0.0, 1e-6, 1.7e-4):
                    t0 = float(rng.uniform(0.0, 0.02))
                    rows = scene.rolling_mean_illuminance_lux(t0, exposure_s, row_offset_s)
                    assert np.array_equal(rows, _rows_of_window_means(scene, t0, exposure_s, row_offset_s))
    finally:
        set_num_threads(threads)
    times = np.linspace(0.001, 0.004, HEIGHT)
    assert np.array_equal(scene.illuminance_lux_row_times(times),
                          np.stack([scene.illuminance_lux(t)[r] for r, t in enumerate(times)]))


def test_rolling_rows_of_a_described_scene_whose_light_a_subclass_changed(tmp_path):
    """A subclass that changes the light gets the frame-by-frame rows (its own light), not the renderer's."""
    base = _scene(tmp_path)

    class Brighter(DescribedScene):
        def illuminance_lux(self, t_s):
            return 2.0 * super().illuminance_lux(t_s)

    brighter = Brighter(base.description)
    rows = brighter.rolling_mean_illuminance_lux(0.003, 1e-3, 1e-4)
    assert np.array_equal(rows, _rows_of_window_means(brighter, 0.003, 1e-3, 1e-4))
    assert np.allclose(rows, 2.0 * base.rolling_mean_illuminance_lux(0.003, 1e-3, 1e-4), rtol=1e-12)


@pytest.mark.parametrize("batch_pixels", [1 << 22, 3 * HEIGHT * WIDTH])
def test_window_means_rendered_in_batches_are_the_midpoint_rule_frame_by_frame(tmp_path, monkeypatch, batch_pixels):
    """A described scene's window mean asks the renderer for its midpoint instants in batches (one batch, or
    batches of three frames): the same values, to the bit, as the midpoint rule one frame at a time; a subclass
    that changes the light gets its own light's mean."""
    import viform.light.scenes as scenes

    monkeypatch.setattr(scenes, "MEAN_BATCH_PIXELS", batch_pixels)
    scene = _scene(tmp_path)

    def frame_by_frame(s, t0, t1, samples):
        times = t0 + (np.arange(samples) + 0.5) * (t1 - t0) / samples
        acc = np.zeros(s.shape)
        for t in times:
            acc += s.illuminance_lux(float(t))
        return acc / samples

    rng = np.random.default_rng(4)
    for exposure_s in (1e-5, 1e-3, 8e-3):
        for samples in (1, 7, 32):
            t0 = float(rng.uniform(0.0, 0.02))
            assert np.array_equal(scene.mean_illuminance_lux(t0, t0 + exposure_s, samples),
                                  frame_by_frame(scene, t0, t0 + exposure_s, samples))

    class Brighter(DescribedScene):
        def illuminance_lux(self, t_s):
            return 2.0 * super().illuminance_lux(t_s)

    brighter = Brighter(scene.description)
    assert np.array_equal(brighter.mean_illuminance_lux(0.004, 0.005), frame_by_frame(brighter, 0.004, 0.005, 32))


def test_a_described_scenes_light_patched_on_the_scene_is_what_its_exposures_see(tmp_path):
    """A described scene whose light is replaced on the scene itself: its means and rolling rows use that light,
    not the renderer's."""
    scene = _scene(tmp_path)
    scene.illuminance_lux = lambda t_s: np.full((HEIGHT, WIDTH), 7.0)
    assert np.array_equal(scene.mean_illuminance_lux(0.001, 0.003), np.full((HEIGHT, WIDTH), 7.0))
    assert np.array_equal(scene.rolling_mean_illuminance_lux(0.001, 1e-3, 1e-4), np.full((HEIGHT, WIDTH), 7.0))
