"""Random layered scenes: plain descriptions that validate, drawn within their ranges, with exact truth."""

from __future__ import annotations

import copy
import math

import imageio.v3 as iio
import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.description import load_description
from viform.light.layered import DescribedScene
from viform.light.random_layers import SCALARS, check_ranges, random_layers, random_layers_description

H, W, T = 32, 48, 0.004


def test_the_description_validates_and_is_a_function_of_the_seed():
    d, drawn = random_layers(11, H, W, T)
    assert load_description(copy.deepcopy(d)) == d  # a plain description: validating it again changes nothing
    assert random_layers_description(11, H, W, T) == d
    assert random_layers_description(12, H, W, T) != d
    assert d["canvas"] == {"width_px": W, "height_px": H, "duration_s": T, "time_reference_s": T / 2}
    assert len(d["layers"]) == len(drawn["objects"])


def test_draws_stay_within_their_ranges():
    ranges = {"n_objects": [2, 3], "speed_px_per_s": [200.0, 400.0], "rotation_rad_per_s": [1.0, 2.0],
              "scale_per_s": [0.5, 1000.0], "peak_lux": 500.0, "dynamic_range_decades": 1.0,
              "contrast_decades": [1.0, 1.0], "flicker_probability": 1.0, "camera_motion_probability": 1.0}
    for seed in range(6):
        d, drawn = random_layers(seed, H, W, T, **ranges)
        assert 2 <= len(drawn["objects"]) <= 3
        assert drawn["camera_pan_px_per_s"] is not None and "camera" in d
        for obj, layer in zip(drawn["objects"], d["layers"], strict=True):
            v = layer["motion"]["velocity"]
            assert 200.0 <= math.hypot(*v["px_per_s"]) <= 400.0
            assert 1.0 <= abs(v["rad_per_s"]) <= 2.0
            assert 0.5 <= abs(v["scale_per_s"]) <= 1.0 / T  # capped: the scale stays in [0.5, 1.5]
            low, high = layer["source"]["image"]["lux"]
            assert 50.0 <= high <= 500.0 and low == pytest.approx(high / 10.0)
            assert "modulation" in layer and obj["flicker"] == layer["modulation"]
        # the background covers the field wherever the camera pans
        bg = d["background"]
        (cx, cy), (sw, sh) = bg["position_px"], bg["source"]["image"]["size_px"]
        travel = math.hypot(*drawn["camera_pan_px_per_s"]) * T / 2
        assert cx - sw / 2 <= -travel and cx + sw / 2 >= W + travel
        assert cy - sh / 2 <= -travel and cy + sh / 2 >= H + travel
    d, drawn = random_layers(0, H, W, T, n_objects=0, camera_motion_probability=0.0, flicker_probability=0.0)
    assert d["layers"] == [] and "camera" not in d and "modulation" not in d["background"]


def test_truth_exists_and_whole_pixel_moves_reproduce_the_light():
    d, _ = random_layers(3, H, W, T, n_objects=[2, 2], object_size_fraction=[0.5, 0.6],
                         camera_motion_probability=0.0, flicker_probability=0.0, rotation_rad_per_s=[0.0, 0.0],
                         scale_per_s=[0.0, 0.0])
    scene = DescribedScene(d)
    assert scene.truth_kinds() == ("motion", "depth", "objects")
    # the drawn scene with its velocities replaced by whole-pixel moves over 2 ms: (+4, −2) px and (−2, +2) px
    moves = [(2000.0, -1000.0), (-1000.0, 1000.0)]
    for layer, v in zip(d["layers"], moves, strict=True):
        layer["motion"]["velocity"]["px_per_s"] = list(v)
        layer["position_px"] = [W / 2, H / 2]  # centred, so both show at t0
    scene = DescribedScene(load_description(d))
    t0, t1 = 0.001, 0.003
    a, b = scene.illuminance_lux(t0), scene.illuminance_lux(t1)
    flow = scene.optical_flow_px(t0, t1)
    labels = scene.object_labels(t0)
    seen = 0
    for oid, (vx, vy) in zip((1, 2), moves, strict=True):
        dx, dy = round(vx * (t1 - t0)), round(vy * (t1 - t0))
        inside = flow.valid & (labels == oid)
        rows, cols = np.nonzero(inside)
        seen += inside.sum()
        np.testing.assert_allclose(flow.flow_px[0][inside], dx, atol=1e-9)
        np.testing.assert_allclose(flow.flow_px[1][inside], dy, atol=1e-9)
        np.testing.assert_allclose(b[rows + dy, cols + dx], a[rows, cols], rtol=1e-9)
    assert seen > 50
    # the background is still (no camera motion): its valid pixels keep their light
    labels1, mixed1 = scene._labels_and_mixed(t1)
    still = flow.valid & (labels == 0) & (labels1 == 0) & ~mixed1
    assert still.any()
    np.testing.assert_allclose(b[still], a[still], rtol=1e-12)
    boxes = {o.object_id for o in scene.objects(t0)}
    assert boxes == {1, 2}
    depth = scene.depth_m(t0)
    assert set(np.unique(depth[labels == 0])) == {d["background"]["depth_m"]}


def test_images_from_a_folder(tmp_path):
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "b.png", rng.integers(0, 256, (20, 30, 3)).astype(np.uint8))
    iio.imwrite(tmp_path / "a.jpg", rng.integers(0, 256, (25, 15)).astype(np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    d, drawn = random_layers(1, H, W, T, images=tmp_path, n_objects=[3, 3])
    paths = {d["background"]["source"]["image"]["path"]} | {l["source"]["image"]["path"] for l in d["layers"]}
    assert paths <= {str((tmp_path / "a.jpg").resolve()), str((tmp_path / "b.png").resolve())}
    assert DescribedScene(d).illuminance_lux(0.001).shape == (H, W)


@pytest.mark.parametrize("ranges, name", [
    ({"speed_px_per_s": [500.0, 100.0]}, "speed_px_per_s"),
    ({"n_objects": [1.5, 2]}, "n_objects"),
    ({"n_objects": [0, 1000]}, "n_objects"),
    ({"peak_lux": -1.0}, "peak_lux"),
    ({"peak_lux": float("nan")}, "peak_lux"),
    ({"flicker_probability": 2.0}, "flicker_probability"),
    ({"dynamic_range_decades": 40.0}, "dynamic_range_decades"),
    ({"speed": 2.0}, "speed"),
])
def test_absurd_ranges_are_refused_naming_the_setting(ranges, name):
    with pytest.raises(ViformError, match=f"setting {name} = "):
        check_ranges(ranges)


def test_bad_image_folders_are_named(tmp_path):
    with pytest.raises(ViformError, match="images = .* no such folder"):
        random_layers(0, H, W, T, images=tmp_path / "absent")
    with pytest.raises(ViformError, match="holds no image files"):
        random_layers(0, H, W, T, images=tmp_path)
    assert set(SCALARS) >= {"peak_lux", "dynamic_range_decades"}
