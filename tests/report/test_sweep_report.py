"""``viform sweep``: the command, its report (self-contained, in a real browser) and its bad-input contract."""

import html
import json
import re
import subprocess

import numpy as np
import pytest

from viform.cli import main
from viform.measure.comparison import METRICS

from .test_compare_report import CHROMIUM, CHROMIUM_FLAGS

ARGS = ["sweep", "dilemma", "--height", "32", "--width", "48", "--duration", "0.012", "--at", "0.004,0.008",
        "--no-progress"]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """A tiny two-sensor sweep through the CLI (in-process, no dask), with demands."""
    tmp = tmp_path_factory.mktemp("sweep")
    out = tmp / "sw"
    code = main([*ARGS, "--workers", "0", "--sensor", "cmos", "--sensor", "seed001-2seg", "--vary",
                 "cmos:exposure_s=1e-4,1e-3", "--require", "underexposed_fraction<=0.2,edge_width_px<=2",
                 "--out", str(out), "--json-file", str(tmp / "s.json")])
    assert code == 0
    return out, json.loads((tmp / "s.json").read_text())


def test_outputs_and_answer(swept):
    out, summary = swept
    assert (out / "report.html").is_file() and (out / "sweep.zarr").is_dir()
    assert summary["n_points"] == 4 and summary["computed"] == 4  # 2 exposures + default; the other's default
    per = summary["answer"]["per_sensor"]
    # the 10 ms default blurs the moving edge over ~18 px: only the short exposures meet edge ≤ 2 px
    assert per["cmos"]["meets"] and per["cmos"]["settings"]["exposure_s"] in (1e-4, 1e-3)
    doc = json.loads((out / "sweep.json").read_text())
    assert len(doc["points"]) == 4 and all(set(METRICS) <= set(p["metrics"]) for p in doc["points"])
    default = next(p for p in doc["points"] if p["sensor"] == "cmos" and p["default"])
    assert default["metrics"]["edge_width_px"] > 2 and default["point_id"] not in summary["answer"].get("meeting", [])


def test_report_is_self_contained(swept):
    out, summary = swept
    text = (out / "report.html").read_text()
    assert "<script" not in text and "<link" not in text
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    # the trade-offs, the curves of the one swept sensor, the best images
    assert text.count("data:image/png;base64,") == 3
    for section in ("answer", "pareto", "curves", "best", "points"):
        assert f"id='{section}'" in text
    assert len(re.findall(r"<tr data-point=", text)) == summary["n_points"]
    assert html.escape(summary["answer"]["sentences"][0]) in text


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed (Debian package 'chromium'; "
                                             ".ci/run installs it)")
def test_report_renders_in_chromium(swept, tmp_path):
    """Chromium draws the report: a picture (figures in colour), not a blank page."""
    out, summary = swept
    url = (out / "report.html").resolve().as_uri()
    shot = tmp_path / "shot.png"
    run = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
                          "--window-size=1280,2400", "--hide-scrollbars", url], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and shot.exists(), run.stderr[-2000:]
    import imageio.v3 as iio

    pixels = iio.imread(shot)[..., :3].reshape(-1, 3)
    assert (pixels < 235).any(axis=1).mean() > 0.05
    assert np.unique(pixels[:: max(1, pixels.shape[0] // 200_000)], axis=0).shape[0] > 200


@pytest.mark.parametrize("extra, needle", [
    (["--sensor", "cmos", "--vary", "exposure=1e-3"], "'exposure' is not a parameter of cmos; allowed: "),
    (["--sensor", "cmos", "--vary", "exposure_s=5e-3:1e-3:1e-3"], "--vary exposure_s=5e-3:1e-3:1e-3: "),
    (["--sensor", "cmos", "--vary", "exposure_s=log:1e-4:1e-2:0"], "gives no points"),
    (["--sensor", "cmos", "--require", "blur<=2"], "--require: 'blur' is not a metric; allowed: "),
    (["--sensor", "cmos", "--require", "edge_width_px=<2"], "--require: 'edge_width_px=<2' is not a demand"),
    (["--sensor", "cmos", "--require", "edge_width_px<=two"], "--require: the bound of"),
    (["--sensor", "nosuch"], "--sensor"),
    (["--sensor", "cmos", "--vary", "exposure_s=0.05"], "--vary: sensor 'cmos' at exposure_s=0.05"),
    (["--sensor", "cmos", "--workers", "1", "--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
])
def test_bad_input_one_line_exit_2_nothing_left(tmp_path, capsys, extra, needle):
    out = tmp_path / "r"
    code = main([*ARGS, *extra, "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and needle in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_flat_metric_is_drawn_flat_not_stretched():
    """A metric that varies by 5·10⁻⁴ of its size over a sweep is not stretched to fill its panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform.report.sweep_report import MIN_SPAN_FRACTION, _floor_span

    fig, ax = plt.subplots()
    values = [0.80196, 0.80251, 0.80230]
    ax.plot(range(3), values)
    half = _floor_span(ax, values)
    lo, hi = ax.get_ylim()
    assert half == pytest.approx((0.80251 - 0.80196) / 2)
    assert hi - lo == pytest.approx(MIN_SPAN_FRACTION * np.mean([min(values), max(values)]))
    # a metric that really varies keeps matplotlib's own limits; all-zero values get one display unit
    fig2, ax2 = plt.subplots()
    assert _floor_span(ax2, [10.0, 20.0, 30.0]) is None
    assert _floor_span(ax2, [0.0, 0.0]) == 0.0 and ax2.get_ylim() == (-0.5, 0.5)
    plt.close("all")


def test_pareto_front_of_one_point_is_visible(swept):
    """Each panel outlines its front's points, so a front of one point is still seen (and named in the legend)."""
    import matplotlib

    matplotlib.use("Agg")
    from viform.report.sweep_report import figure_pareto

    out, _ = swept
    doc = json.loads((out / "sweep.json").read_text())
    doc.setdefault("records", doc.get("points"))
    fig = figure_pareto(doc, doc["pareto"])
    for ax in fig.axes:
        fronts = [c for c in ax.collections if c.get_label().startswith("Pareto front")]
        assert fronts and len(fronts[0].get_offsets()) >= 1
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any(lb.startswith("Pareto front") for lb in labels)
