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
                         timeout=1800)  # a hang guard only: never reached by a slow machine
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
    # the library names its parameters; the command maps each to its flag (SWEEP_FLAGS)
    (["--sensor", "cmos", "--duration", "20"], "--duration = 20 s is not allowed"),
    (["--sensor", "cmos", "--at", "0.5"], "--at: instant 0.5 s is outside the clip"),
    (["--sensor", "cmos", "--spike-image", "x"], "--spike-image = 'x' is not allowed"),
    (["--sensor", "cmos", "--objective", "blur"], "--objective: 'blur' is not a metric"),
    (["--sensor", "cmos", "--workers", "-1"], "--workers = -1 is not allowed"),
    (["--sensor", "cmos", "--worker-memory", "lots"], "--worker-memory = 'lots' is not allowed"),
    (["--sensor", "spikeone", "--device", "gpu"], "--device"),
    (["--sensor", "cmos", "--device", "cuda"], "--device = 'cuda' runs the spike camera's simulation on a GPU"),
    (["--sensor", "cmos", "--vary", "scene:nosuch=1"], "--vary scene:nosuch=1: 'nosuch' is not a numeric parameter"),
    (["--sensor", "cmos", "--vary", "scene:brightness=-1"], "--vary: the scene at brightness=-1 cannot be made"),
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
    # the panel's note names the value: a constant (data rate) is said to be one, not "within ±0"
    from viform.report.sweep_report import _flat_text

    assert _flat_text([40.96, 40.96], 0.0) == "the same at every point: 40.96"
    assert _flat_text(values, half) == f"flat: every point within ±{half:.2g} of {(0.80196 + 0.80251) / 2:.4g}"


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


def test_tracking_a_scene_without_objects_is_refused(tmp_path, capsys):
    """translating has no objects: --tracking is refused in one line (exit 2), nothing written."""
    out = tmp_path / "r"
    code = main(["sweep", "translating", "--sensor", "cmos", "--vary", "exposure_s=0.001", "--tracking",
                 "--height", "32", "--width", "48", "--duration", "0.012", "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "--tracking: scene 'translating' has no objects to track" in err and not out.exists()


def test_no_require_prints_no_meets(tmp_path, capsys):
    """Without --require nothing "meets": the console names each sensor's best by the objective and says no
    demands were given."""
    code = main([*ARGS, "--workers", "0", "--sensor", "cmos", "--vary", "exposure_s=1e-3", "--out",
                 str(tmp_path / "sw")])
    out = capsys.readouterr().out
    assert code == 0
    assert "meets" not in out and "No demands were given" in out and "cmos    best" in out


def test_cuda_without_a_gpu_is_one_line(tmp_path, capsys):
    from viform.sensors.spike_cuda import cuda_available

    if cuda_available():
        pytest.skip("this machine has a CUDA GPU")
    out = tmp_path / "r"
    code = main([*ARGS, "--sensor", "spikeone", "--device", "cuda", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and err.count("--device = 'cuda'") == 1, err
    assert not out.exists()
    # the same line as every command with --device (here: simulate)
    code = main(["simulate", "hdr", "--duration", "0.001", "--height", "8", "--width", "8", "--out",
                 str(tmp_path / "x.dat"), "--device", "cuda"])
    assert code == 2 and capsys.readouterr().err.strip() == err
    # auto: the CPU where there is no GPU (a sweep runs; its document says where)
    code = main([*ARGS, "--sensor", "spikeone", "--vary", "spikeone:threshold_level=12", "--workers", "0",
                 "--device", "auto", "--out", str(out), "--no-progress"])
    assert code == 0 and json.loads((out / "sweep.json").read_text())["device"] == "cpu"


def test_scene_parameters_from_the_command_line(tmp_path, capsys):
    """--vary scene:brightness=… shoots every point at each light level and answers per level; --list-parameters
    names the scene's parameters."""
    code = main([*ARGS, "--workers", "0", "--sensor", "cmos", "--vary", "scene:brightness=0.5,2", "--require",
                 "underexposed_fraction<=0.5", "--out", str(tmp_path / "sw")])
    out = capsys.readouterr().out
    assert code == 0
    assert "At scene brightness = 0.5:" in out and "At scene brightness = 2:" in out
    assert main(["sweep", "dilemma", "--sensor", "cmos", "--list-parameters"]) == 0
    listed = capsys.readouterr().out
    assert "scene (dilemma; vary as scene:PARAM): brightness=1.0" in listed


def test_console_says_where_the_points_ran():
    """The first console line names the workers, and how many points this process shot while they started."""
    from viform.report.sweep_report import console_lines

    doc = {"n_points": 5, "computed": 5, "reused": 0, "seconds": 3.0, "cpu_seconds": 2.0, "workers": 2,
           "computed_here": 2, "answer": {"per_sensor": {}, "sentences": [], "objective": "psnr_log_db"}}
    assert console_lines(doc)[0] == ("5 points (5 computed, 0 reused) in 3.0 s on 2 dask workers (2 of the points "
                                     "in this process while they started), 2.0 CPU-s")
    doc.update(workers=0, computed_here=5)
    assert console_lines(doc)[0] == "5 points (5 computed, 0 reused) in 3.0 s on no dask workers, 2.0 CPU-s"


def test_a_folder_of_another_sweep_is_refused_before_the_compile_notice(swept, capsys, monkeypatch):
    """--out holding a sweep of other options (here another --duration) is refused in one line, exit 2,
    even on a first run whose spike sensor would announce its compile first; the folder is left as it was."""
    monkeypatch.setattr("viform.cli.compare.kernels_cached", lambda: False)  # as on a first run
    out, _ = swept
    before = (out / "sweep.json").read_bytes()
    args = [a if a != "0.012" else "0.016" for a in ARGS]
    code = main([*args, "--workers", "0", "--sensor", "spikeone", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert f"--out {str(out)!r} holds a sweep made with other options" in err
    assert (out / "sweep.json").read_bytes() == before


@pytest.mark.parametrize("text", ["[]", '{"context": 5}', "not json"])
def test_a_sweep_json_that_is_not_a_sweep_is_refused_and_kept(tmp_path, capsys, text):
    """--out holding a sweep.json viform cannot read as a sweep (another document, a damaged one) is refused
    in one line, exit 2, and the file is left as it was (never written over)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.json").write_text(text)
    code = main([*ARGS, "--workers", "0", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert f"--out = {str(out)!r} holds a sweep.json viform cannot read as a sweep" in err
    assert (out / "sweep.json").read_text() == text and sorted(p.name for p in out.iterdir()) == ["sweep.json"]
