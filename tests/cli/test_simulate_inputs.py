"""viform simulate handles image and video inputs as documented (issue 15, item 6)."""

import imageio.v3 as iio
import numpy as np
import pytest

from viform.cli import main
from viform.light.catalog import fit_shape, load_scene
from viform.light.scenes import image_to_lux
from viform.stream.io import open_spikes


def test_height_or_width_resizes_an_image_keeping_its_aspect_ratio(tmp_path):
    image = tmp_path / "tall.png"
    iio.imwrite(image, np.full((200, 300), 128, np.uint8))  # 200 rows × 300 columns
    out = tmp_path / "s.npz"
    assert main(["simulate", str(image), "--duration", "0.001", "--height", "100", "--out", str(out)]) == 0
    assert open_spikes(out).shape[1:] == (100, 150)


def test_both_sides_that_would_stretch_are_refused(tmp_path, capsys):
    image = tmp_path / "tall.png"
    iio.imwrite(image, np.full((200, 300), 128, np.uint8))
    rc = main(["simulate", str(image), "--duration", "0.001", "--height", "300", "--width", "200",
               "--out", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err
    assert rc == 2 and "stretch" in err and "--height" in err and err.count("\n") == 1
    assert not (tmp_path / "s.npz").exists()


def test_fit_shape_keeps_ratio():
    assert fit_shape((200, 300), None, 150) == (100, 150)
    assert fit_shape((200, 300), 400, 600) == (400, 600)
    assert fit_shape((200, 300), None, None) == (200, 300)


def test_float_images_are_lux_whatever_max_lux():
    """A float image holds lux; --max-lux is the full scale of integer images only."""
    assert image_to_lux(np.array([[0.5, 250.0]]), 4.0).tolist() == [[0.5, 250.0]]
    assert image_to_lux(np.array([[255]], np.uint8), 4.0).tolist() == [[4.0]]


def test_max_lux_must_be_positive_even_for_builtin_scenes(tmp_path, capsys):
    rc = main(["simulate", "translating", "--duration", "0.001", "--max-lux", "-1", "--out", str(tmp_path / "s.npz")])
    assert rc == 2 and "--max-lux" in capsys.readouterr().err


def test_short_video_warns_that_its_last_frame_is_held(tmp_path, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(3):
        iio.imwrite(folder / f"{k:03d}.png", np.full((8, 8), 40 * (k + 1), np.uint8))
    rc = main(["simulate", str(folder), "--frame-rate-hz", "1000", "--duration", "0.01",
               "--out", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err
    assert rc == 0 and "warning" in err and "0.003 s" in err


def test_video_without_a_frame_rate_names_the_flag(tmp_path, capsys):
    """The library names its parameter, each command the flag the user types (highspeed's is --scene-fps)."""
    folder = tmp_path / "frames"
    folder.mkdir()
    iio.imwrite(folder / "000.png", np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="give it with frame_rate_hz"):
        load_scene(str(folder), 4, 4)
    assert main(["simulate", str(folder), "--duration", "0.001", "--out", str(tmp_path / "s.npz")]) == 2
    assert "give it with --frame-rate-hz" in capsys.readouterr().err
    assert main(["highspeed", str(folder), "--out", str(tmp_path / "hs")]) == 2
    assert "give it with --scene-fps" in capsys.readouterr().err


def test_a_video_lasts_its_own_length_without_duration(tmp_path, capsys):
    """Issue 27 item 9: a video declares its length; --duration is needed only to change it."""
    video = tmp_path / "v.mp4"
    iio.imwrite(video, np.full((4, 16, 16), 90, np.uint8), extension=".mp4", fps=100, codec="libx264")
    out = tmp_path / "s.npz"
    assert main(["simulate", str(video), "--out", str(out), "--json"]) == 0
    summary = __import__("json").loads(capsys.readouterr().out)
    assert summary["duration_from"] == "the video's length"
    assert open_spikes(out).n_ticks == round(4 / 100 * 40_000)
