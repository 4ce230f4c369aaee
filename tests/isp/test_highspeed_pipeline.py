"""End to end: LUX13HS-like sensor → AE → DDR ring → decimation → equalization → link, and the CLI."""

import json

import numpy as np
import pytest

from viform.cli import main
from viform.isp.highspeed_pipeline import (
    HighSpeedConfig,
    ScaledScene,
    StepsScene,
    lux13hs_pixel_parameters,
    run_highspeed,
)
from viform.light.scenes import StillScene, TranslatingScene


def test_lux13hs_pixel_mapping():
    p = lux13hs_pixel_parameters()
    assert p.optics.quantum_efficiency == 0.45
    assert p.full_well_electrons == 30_000 and p.read_noise_electrons == 15
    assert p.prnu_fraction == 0.015
    assert p.dsnu_electrons == pytest.approx(0.005 * 30_000)       # 0.5 % of full scale
    assert p.adc_bits == 10
    assert p.system_gain_dn_per_e == pytest.approx(40e-6 * 1023 / 1.2)


def test_steps_scene_window_mean_is_exact():
    base = StillScene(np.full((2, 2), 10.0))
    sc = StepsScene(base, [(1.0, 10.0), (2.0, 0.1)])
    assert sc.mean_illuminance_lux(0.5, 1.5)[0, 0] == pytest.approx(0.5 * 10 + 0.5 * 100)
    assert sc.mean_illuminance_lux(1.5, 2.5)[0, 0] == pytest.approx(0.5 * 100 + 0.5 * 10)
    assert ScaledScene(base, 3).illuminance_lux(0)[0, 0] == 30


def test_run_at_seed_rate_with_decimation_and_equalization():
    scene = ScaledScene(TranslatingScene(36, 64), 60.0)
    r = run_highspeed(scene, HighSpeedConfig(n_frames=30))
    assert r.timing["frame_rate_hz"] == pytest.approx(1e8 / 6e4)
    assert r.plan["decimation"] == 3
    # Frames 0, 3, …, 24: the transfer of frame 27 (3.0006 frame periods) ends after the record.
    np.testing.assert_array_equal(r.transmitted_indices, np.arange(0, 27, 3))
    assert r.output_frames.shape == (9, 36, 64)
    assert r.account["frames_transmitted"] == 9 and r.account["frames_dropped"] == 0
    assert np.all(r.exposure_cycles >= 1) and np.all(r.exposure_cycles <= 59_999)
    assert abs(r.metered_gray[-1] - 128) <= 15
    # Exposure start/end inside the frame period: the exposure is whole cycles.
    assert np.allclose(r.exposure_s * 1e8, r.exposure_cycles)


def test_slow_link_forced_decimation_loses_frames():
    """GigE carries 129 fps at 1280 × 720; forcing 2:1 (833 fps) overflows the ring, whose
    2 330 frames last ≈ 1.6 s at that backlog: a 1.6 s window shows the first losses."""
    scene = ScaledScene(TranslatingScene(4, 4), 60.0)
    r = run_highspeed(scene, HighSpeedConfig(n_frames=3000, interface="gige", decimation=2, ae=False,
                                             equalize=False))
    assert r.account["selected_but_overwritten"] > 0
    assert r.account["frames_dropped"] > 0
    sent_rate = r.account["frames_transmitted"] / (3000 / r.timing["frame_rate_hz"])
    assert sent_rate <= r.plan["link_max_frame_rate_hz"] * 1.01


def test_cli_writes_video_plot_report(tmp_path):
    out = tmp_path / "hs"
    rc = main(["highspeed", "translating", "--frames", "40", "--render", "64x36", "--steps", "0.01:10",
               "--out", str(out)])
    assert rc == 0
    assert (out / "video.gif").stat().st_size > 0 and (out / "exposure.png").stat().st_size > 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["frames_captured"] == 40
    # Frames 0, 3, …, 33: each 3.0006-frame transfer must end within the 40-frame recording.
    assert rep["frames_transmitted"] == 12
    assert rep["frames_captured"] == (rep["frames_transmitted"] + rep["frames_dropped"]
                                      + rep["frames_only_in_buffer"])
    assert rep["link"]["decimation"] == 3
    assert not list(out.glob(".*"))  # no temporary files left


def test_cli_console_counts_add_up_and_plan_matches_figures(tmp_path, capsys):
    """The console's frame counts add up (captured = transmitted + still in the ring + lost), and
    the run describes its 3:1 sampling with the same words as ``highspeed-figures``."""
    import re

    rc = main(["highspeed", "translating", "--frames", "10", "--render", "32x18", "--steps", "none",
               "--out", str(tmp_path / "hs")])
    assert rc == 0
    text = capsys.readouterr().out
    m = re.search(r"captured (\d+) = transmitted (\d+) \+ still in the DDR ring (\d+) .*\+ lost (\d+)", text)
    assert m, text
    cap, sent, ring, lost = map(int, m.groups())
    assert (cap, sent) == (10, 2) and cap == sent + ring + lost
    sampling = re.search(r"sampling: (.*) -> ", text).group(1)
    assert "link alone: 4:1" in sampling and "overruns after" in sampling
    assert main(["highspeed-figures"]) == 0
    assert sampling in capsys.readouterr().out


@pytest.mark.parametrize("args, name", [
    (["--roi", "1400x720"], "roi"),
    (["--interface", "gige", "--max-decimation", "8"], "interface"),
    (["--target", "300"], "target"),
    (["--exposure-us", "700"], "exposure"),
    (["--interface", "firewire"], "interface"),
    (["--ae-saturated-cut", "1.5"], "ae-saturated-cut"),
])
def test_cli_bad_input_one_line_exit_2(tmp_path, capsys, args, name):
    extra = ["--frames", "2", "--render", "16x9", "--out", str(tmp_path / "x")]
    rc = main(["highspeed", "translating", *args, *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and "Traceback" not in err[0]
    assert name in err[-1] and err[-1].startswith("viform: error:")
    assert not (tmp_path / "x").exists()  # no partial output


def test_same_frame_equalization_is_the_default_and_does_not_flash():
    """Seed 002 §3.2.2: each frame is equalized with its own histogram (gathered while it is
    written to DDR4). Around a 10× light step the output mean gray stays near mid-scale
    (equalization maps the cumulative histogram onto 0–255, mean ≈ 127.5 for any frame);
    the previous-frame table sends the first frame after the step to ≈ 240 (white flash)."""
    from viform.isp.highspeed_pipeline import equalizer_step_flash

    assert HighSpeedConfig().eq_source == "same"
    same = equalizer_step_flash("same")
    prev = equalizer_step_flash("previous")
    # Noise-limited: a 36×64 frame's equalized mean is 127.5 ± a few levels of tie-breaking.
    assert all(abs(m - 128) < 12 for m in same)
    assert prev[0] < 40            # first frame passes unequalized (dark)
    assert prev[1] > 200           # flash: the dark frame's table applied to the bright frame
    assert abs(prev[2] - same[2]) < 1  # the flash lasts one frame


def test_fig9_before_after_ae_and_equalization():
    """Seed 002 Fig. 9: AE lowers the brightness of an over-exposed image; equalization
    raises the contrast of a dark one. Model: AE off at 500 µs saturates most pixels; AE on
    brings the mean gray into the seed's dead band 128 ± 15; equalization spreads a dark
    frame (gray 1–27) over 0–255 (1st–99th percentile spread > 200 levels)."""
    from viform.isp.highspeed_pipeline import before_after

    p = before_after(render_shape=(45, 80), n_frames=30)
    assert p["AE off"]["saturated_fraction"] > 0.5
    assert abs(p["AE on"]["mean_gray"] - 128) <= 15 + 5   # band ± noise of the metered mean
    assert p["AE on"]["saturated_fraction"] < p["AE off"]["saturated_fraction"] / 3
    lo_off, hi_off = p["equalization off"]["gray_p1_p99"]
    lo_on, hi_on = p["equalization on"]["gray_p1_p99"]
    assert hi_off - lo_off < 40 and hi_on - lo_on > 200


def test_highspeed_figures_table_and_json(tmp_path, capsys):
    out = tmp_path / "f"
    assert main(["highspeed-figures", "--json-file", str(tmp_path / "f.json")]) == 0
    text = capsys.readouterr().out
    assert "published" in text and "paper" not in text and "fps" in text and "{" not in text
    data = json.loads((tmp_path / "f.json").read_text())
    assert data["reduced_2500fps_full_frame"]["fps_1280x864"] == pytest.approx(2500, rel=1e-3)
    assert main(["highspeed-figures", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["cameralink_seed"] == "555 fps"
    del out


def test_image_of_another_shape_is_cropped_not_stretched():
    """Issue 15: a 512 × 512 image was stretched to the 320 × 180 grid. Now its centre
    512 × 288 (16:9) is kept and resized: a square stays square (rows and columns scale by
    the same 1.6)."""
    from viform.isp.highspeed_pipeline import AspectFitScene

    img = np.zeros((512, 512))
    img[192:320, 192:320] = 100.0                      # a 128-px square in the centre
    fit = AspectFitScene(StillScene(img), 180, 320)
    assert fit.crop == (288, 512)
    out = fit.illuminance_lux(0.0)
    rows = np.nonzero(out.max(axis=1) > 50)[0]
    cols = np.nonzero(out.max(axis=0) > 50)[0]
    assert abs((rows[-1] - rows[0]) - (cols[-1] - cols[0])) <= 1   # still square
    assert (cols[-1] - cols[0] + 1) == pytest.approx(128 / 1.6, abs=1.5)


def test_cli_json_flag_prints_the_report(tmp_path, capsys):
    rc = main(["highspeed", "translating", "--frames", "6", "--render", "32x18", "--steps", "none",
               "--out", str(tmp_path / "o"), "--json", "--json-file", str(tmp_path / "r.json")])
    assert rc == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["frames_captured"] == 6
    assert json.loads((tmp_path / "r.json").read_text())["frames_captured"] == 6


def test_exposure_figure_legends_cover_no_trace():
    """Issue 27 item 15: the legend sat on the exposure trace after the light step. Legends now
    stand beside the plots: no legend box overlaps either axes."""
    import matplotlib

    matplotlib.use("Agg")
    from viform.isp.highspeed_pipeline import exposure_figure

    scene = StepsScene(ScaledScene(TranslatingScene(16, 24), 60.0), [(0.01, 10.0)])
    result = run_highspeed(scene, HighSpeedConfig(n_frames=30))
    fig = exposure_figure(result, [0.01])
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    axes = [ax.get_window_extent(renderer) for ax in fig.axes]
    legends = [ax.get_legend().get_window_extent(renderer) for ax in fig.axes if ax.get_legend() is not None]
    assert len(legends) == 2
    for box in legends:
        assert not any(box.overlaps(a) for a in axes)
