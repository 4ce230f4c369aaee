"""The spike chip's experiment figures (seed 000 §6, Figs. 1, 3–5) and ``viform chip-figures``."""

import json

import numpy as np
import pytest

from viform.cli import main
from viform.light.articulated import WavingHandScene
from viform.report.chip_figures import (
    accumulation_counts,
    first_spikes,
    hand_stream,
    interval_display,
    spike_train_of,
)


def test_fig1_spike_train_and_first_spikes():
    """Seed 000 Fig. 1: pulses 1–4 equal; pulse 5 shorter (the light rose during it); 6–11
    half as wide (twice the light); 12 longer (the light fell); 13–14 twice as wide as 1–4
    (half the light). 14 pulses reduce to the first spikes 1, 5, 6, 12, 13 (§5.2). Exact."""
    t = spike_train_of((1 / 6, 1 / 3, 1 / 12), (26.0, 21.0, 33.0))
    w = np.diff(np.concatenate([[0.0], t]))
    assert t.size == 14
    assert w[:4] == pytest.approx([6] * 4)
    assert 3 < w[4] < 6
    assert w[5:11] == pytest.approx([3] * 6)                  # half of pulses 1–4
    assert 6 < w[11] < 12
    assert w[12:] == pytest.approx([12, 12])                  # twice pulses 1–4
    assert (first_spikes(t) + 1).tolist() == [1, 5, 6, 12, 13]


@pytest.fixture(scope="module")
def small_run():
    return hand_stream(size=48, n_ticks=260, seed=2)


def test_fig3_accumulation_grows_and_blurs(small_run):
    """Seed 000 Fig. 3: 1, 2, 5 ticks show single spikes (white dots); by 10 ms (200 ticks)
    the hand is blurred. Count/n is the same rate for every n (Poisson: the 200-tick mean
    rate equals the 50-tick one within 3σ of the 50-tick mean over 2 304 pixels)."""
    stream, scene, _ = small_run
    c = accumulation_counts(stream, (1, 2, 5, 50, 200))
    assert set(np.unique(c[1])) <= {0, 1}                     # one tick: spike or not
    r50, r200 = c[50].mean() / 50, c[200].mean() / 200
    sigma = np.sqrt(c[50].mean()) / 50 / np.sqrt(c[50].size)
    assert abs(r200 - r50) < 3 * sigma + 0.01 * r50
    # The hand moves ≈ 0.05 px in one tick and several px in 10 ms (motion blur).
    scale = 48 / 240
    assert scene.hand_speed_px_per_s(0.0) / 20e3 < 0.1
    assert scene.hand_speed_px_per_s(0.005) * 0.01 > 8 * scale


def test_fig4_interval_image_has_no_motion_blur(small_run):
    """Seed 000 Fig. 4: the interval image at the last tick (255 − τ) follows the light at
    that instant; the 200-tick accumulation is blurred. Near the hand, the interval image's
    1/τ correlates with the true light at that tick better than the accumulation does."""
    from viform.imaging.interval import interval_ticks

    stream, scene, _ = small_run
    k = 199
    tau, cens = interval_ticks(stream, [k])
    assert not cens.any()
    acc = accumulation_counts(stream, (200,))[200]
    truth = scene.illuminance_lux((k + 0.5) / stream.clock_hz)
    rows = slice(0, 30)
    cols = slice(24, 48)
    c_int = np.corrcoef((1.0 / tau[0])[rows, cols].ravel(), truth[rows, cols].ravel())[0, 1]
    c_acc = np.corrcoef(acc[rows, cols].ravel(), truth[rows, cols].ravel())[0, 1]
    assert c_int > c_acc
    disp = interval_display(tau[0], "minmax")
    assert disp[tau[0] == tau[0].min()].min() == 255 and disp[tau[0] == tau[0].max()].max() == 0


def test_chip_figures_cli(tmp_path, capsys):
    out = tmp_path / "chip"
    assert main(["chip-figures", "--out", str(out), "--size", "24", "--ticks", "60", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["clock_hz"] == 20e3 and data["fig1"]["first_spikes"] == [1, 5, 6, 12, 13]
    for f in data["files"]:
        assert (out / f).stat().st_size > 0
    assert main(["chip-figures", "--out", str(out), "--size", "8"]) == 2
    assert "size" in capsys.readouterr().err


def test_waving_hand_scene_is_valid_light():
    s = WavingHandScene(32, 40)
    img = s.illuminance_lux(0.01)
    assert img.shape == (32, 40) and img.min() >= 0 and img.max() <= s.skin_lux + 1e-9


def test_figures_have_no_text_cut_off_or_overlapping(small_run, check_layout):
    """Fig. 5's pixel numbers sat on the neighbouring circles along the hand's arc (pixels a
    few apart) and the row numbers left of the axes: every number is now clear of every circle
    and of the other numbers, and every text inside the figure. Figs. 1, 3 and 4 likewise."""
    from viform.imaging.interval import interval_ticks
    from viform.report.chip_figures import fig1_figure, fig3_figure, fig4_figure, fig5_figure, pick_pixels

    stream, scene, p = small_run
    check_layout(fig1_figure()[0])
    counts = accumulation_counts(stream, (1, 2, 5, 50, 200))
    check_layout(fig3_figure(counts, stream.clock_hz, p.name))
    tau, _ = interval_ticks(stream, [199])
    check_layout(fig4_figure(counts[200], tau[0], "minmax", 200, stream.clock_hz))
    fig, seqs = fig5_figure(stream, [24, 74, 124, 174], pick_pixels(scene), "minmax", 200)
    assert len(seqs) == 10
    assert [t.get_text() for t in fig.axes[-1].get_yticklabels()] == [str(j) for j in range(1, 11)]
    check_layout(fig)
