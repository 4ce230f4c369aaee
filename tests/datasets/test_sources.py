"""Source clips fitted to the sensor without stretching; unreadable frames and an unreachable
scheduler named before anything is written (issue 27, items 5, 7 and 12)."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from viform._validate import ViformError
from viform.datasets import build
from viform.datasets.sources import SourceClip, describe_fit, fit_to_sensor, read_clip


def _disc_clip(folder, n=2, bad=None):
    folder.mkdir(parents=True)
    y, x = np.mgrid[:128, :160]
    for k in range(n):
        iio.imwrite(folder / f"{k:03d}.png", ((np.hypot(y - 64, x - 80) < 30) * 255).astype(np.uint8))
    if bad is not None:
        (folder / bad).write_bytes(np.random.default_rng(0).bytes(500))
    return SourceClip(folder.name, str(folder), "frames")


def test_fit_scales_once_and_crops_the_excess():
    fit = fit_to_sensor((128, 160), (250, 400))
    assert fit["scale"] == 2.5 and fit["scaled_shape"] == [320, 400] and fit["crop"] == [35, 0]
    assert "70 rows cropped (centred)" in describe_fit(fit) and "aspect ratio kept" in describe_fit(fit)
    same = fit_to_sensor((125, 200), (250, 400))
    assert same["scaled_shape"] == [250, 400] and "nothing cropped" in describe_fit(same)


def test_a_disc_stays_a_disc_on_a_sensor_of_another_aspect_ratio(tmp_path):
    """160×128 sources on the 400×250 SpikeOne were stretched 2.5× across and 1.95× down."""
    frames, _, fit = read_clip(_disc_clip(tmp_path / "disc"), 250, 400, max_lux=100.0)
    assert frames.shape == (2, 250, 400) and fit["scale"] == 2.5
    rows, cols = np.nonzero(frames[0] > 50.0)
    height, width = rows.max() - rows.min() + 1, cols.max() - cols.min() + 1
    assert abs(height - width) <= 1 and abs(width - 2.5 * 59) <= 3  # a 59 px disc, scaled 2.5×


def test_an_unreadable_frame_is_named(tmp_path):
    clip = _disc_clip(tmp_path / "b", bad="001b.png")
    with pytest.raises(ViformError, match=r"clip 'b': frame file '.*001b\.png' is not a readable image"):
        read_clip(clip, 250, 400, max_lux=100.0)


def test_a_failing_clip_is_reported_not_raised_on_the_worker(tmp_path, settings):
    """A clip's bad data comes back as a result (no "Compute Failed" traceback in the worker's log)."""
    clip = _disc_clip(tmp_path / "src" / "b", bad="001b.png")
    result = build._convert_or_report(build.ClipTask(clip, str(tmp_path / "out"), settings))
    assert result["status"] == "failed" and "001b.png" in result["error"]


def test_an_unreachable_scheduler_leaves_no_dataset(tmp_path, settings, monkeypatch):
    def refuse(*args, **kwargs):
        raise ViformError("--scheduler 'tcp://127.0.0.1:1': could not connect")

    monkeypatch.setattr(build, "open_client", refuse)
    _disc_clip(tmp_path / "src" / "a")
    with pytest.raises(ViformError, match="could not connect"):
        build.build_dataset(tmp_path / "src", tmp_path / "ds", settings, scheduler="tcp://127.0.0.1:1")
    assert not (tmp_path / "ds").exists()
