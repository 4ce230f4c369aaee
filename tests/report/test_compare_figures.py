"""The comparison figures a reader sees: no label cut off at the figure's edge (the dilemma
plot's long sensor names), no text drawn over another, one colour bar per quantity."""

import pytest

from viform.light.catalog import builtin_scene
from viform.report import compare_report as cr


@pytest.fixture(scope="module")
def small():
    """Every sensor but the slow-to-compile gated one on a tiny dilemma scene (long labels, 10 points)."""
    scene = builtin_scene("dilemma", 32, 64)
    sensors = ["spikeone", "cmos-short", "cmos", "seed001-2seg", "seed003-4t", "seed003-overflow", "highspeed"]
    return cr.run_comparison(scene, 0.02, sensors, [0.01], seed=1, progress=False)


def test_dilemma_legend_and_numbers_fit(small, check_layout):
    """Before: legend labels ran off the right edge; the legend now sits inside, wrapped, and names every point."""
    fig = cr.figure_dilemma(small)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    shots = [s for s in small["shots"] if not s.skipped and s.lux_units]
    # every sensor, the scene's demand, the region meeting both, and the dotted frame-interval line
    # (issue 27: a 130 µs integration repeated every 16.7 ms is drawn on to its frame interval)
    assert len(labels) == len(shots) + 3
    assert any(label.startswith("dotted: from the integration time") for label in labels)
    dotted = [line for line in fig.axes[0].lines if line.get_linestyle() == ":" and len(line.get_xdata()) == 2]
    seg = next(s for s in shots if s.key == "seed001-2seg")
    assert any(line.get_xdata()[1] == pytest.approx(1 / seg.frame_rate_hz) for line in dotted)
    check_layout(fig)


@pytest.mark.parametrize("which", ["instant", "errors", "scene"])
def test_image_grids_fit(small, check_layout, which):
    """Panel titles are wrapped to the panel's width: none runs into its neighbour or off the figure."""
    fig = {"instant": lambda: cr.figure_instant(small, 0), "errors": lambda: cr.figure_errors(small, 0),
           "scene": lambda: cr.figure_scene(small)}[which]()
    check_layout(fig)


def test_narrow_grid_wraps_its_title(check_layout):
    """Two sensors make a two-panel-wide figure: the long figure title wraps instead of running off."""
    scene = builtin_scene("dilemma", 32, 64)
    res = cr.run_comparison(scene, 0.02, ["cmos"], [0.01], seed=1, progress=False)
    fig = cr.figure_errors(res, 0)
    assert "\n" in fig._suptitle.get_text()
    check_layout(fig)


def test_gated_figure_fits(check_layout):
    """The gated camera's frame beside the passive truth: two colour bars (lux, e⁻), both inside."""
    scene = builtin_scene("night-road-fog", 32, 64)
    res = cr.run_comparison(scene, 0.02, ["gated"], [0.01], seed=1, progress=False)
    fig = cr.figure_gated(res)
    labels = [c.get_ylabel() for a in fig.axes for c in a.child_axes]
    assert any("lux" in lb for lb in labels) and any("e⁻" in lb for lb in labels)
    check_layout(fig)


def test_long_legend_labels_break_at_their_separator():
    """A long sensor label breaks at " · ", so no legend line ends in a dangling separator (it read as a cut)."""
    from viform.report.compare_report import _wrap_label

    label = "1  spike (SpikeOne, Q = 16 250 e⁻, 40 kHz) · accumulation 1 ms"
    lines = _wrap_label(label, 44).splitlines()
    assert len(lines) == 2 and lines[1].strip() == "· accumulation 1 ms"
    assert not any(line.rstrip().endswith("·") for line in lines) and all(len(line) <= 44 for line in lines)
    assert _wrap_label("4  CMOS 1 ms (cmos-short)", 44) == "4  CMOS 1 ms (cmos-short)"
