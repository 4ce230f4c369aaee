"""``viform compare`` / ``viform demo``: the report in a real browser, metrics.json, the CLI contract."""

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from viform.cli import main
from viform.measure.comparison import METRICS
from viform.report.compare_report import compare

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The comparison on a tiny dilemma scene (every sensor; gated is refused: no range)."""
    out = tmp_path_factory.mktemp("compare")
    doc = compare("dilemma", out, None, duration_s=0.012, height=32, width=64, seed=1, instants_s=[0.004, 0.008],
                  progress=False)
    return out, doc


def test_metrics_json_holds_every_sensor_and_metric(report):
    out, doc = report
    saved = json.loads((out / "metrics.json").read_text())
    keys = set(saved["sensors"])
    assert {"spikeone-accumulation", "spikeone-interval", "cmos", "cmos-short", "seed001-2seg", "seed001-3seg",
            "seed003-4t", "seed003-overflow", "highspeed", "gated"} <= keys
    assert "range" in saved["sensors"]["gated"]["skipped"]
    for key, entry in saved["sensors"].items():
        if entry["skipped"]:
            continue
        assert set(METRICS) <= set(entry["metrics"]), key
        m = entry["metrics"]
        assert 0 <= m["saturated_fraction"] <= 1 and 0 <= m["underexposed_fraction"] <= 1
        assert m["data_rate_mb_per_s"] > 0 and m["latency_s"] > 0
    # data rates follow from the outputs: 1 bit per pixel per 40 kHz tick against 12-bit frames at 30 fps
    assert saved["sensors"]["spikeone-interval"]["metrics"]["data_rate_mb_per_s"] == pytest.approx(32 * 64 * 40e3 / 8e6)
    assert saved["sensors"]["cmos"]["metrics"]["data_rate_mb_per_s"] == pytest.approx(32 * 64 * 12 * 30 / 8e6)
    assert saved["verdict"] and all(isinstance(line, str) for line in saved["verdict"])
    assert saved["demand"]["dynamic_range_db"] >= 120


def test_report_is_self_contained(report):
    out, _ = report
    text = (out / "report.html").read_text()
    assert "<script" not in text and "<link" not in text
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    # scene, summary + images and errors at 2 instants + the vision section's tracks (the scene has object truth)
    assert text.count("data:image/png;base64,") == 2 + 2 * 2 + 1


class _Sections(HTMLParser):
    """Collects, per sensor section (id="sensor-KEY"), the data-metric cells it holds."""

    def __init__(self):
        super().__init__()
        self.sections, self._stack = {}, []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "div":
            key = attrs.get("id", "")
            self._stack.append(key[len("sensor-"):] if key.startswith("sensor-") else None)
            if self._stack[-1]:
                self.sections[self._stack[-1]] = set()
        current = next((k for k in reversed(self._stack) if k), None)
        if current and "data-metric" in attrs:
            self.sections[current].add(attrs["data-metric"])

    def handle_endtag(self, tag):
        if tag == "div" and self._stack:
            self._stack.pop()


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed (Debian package 'chromium'; "
                                             ".ci/run installs it)")
def test_report_renders_in_chromium(report, tmp_path):
    """Chromium renders the report: the DOM holds every sensor's section and every metric, and the
    screenshot is a picture, not a blank page."""
    out, doc = report
    url = (out / "report.html").resolve().as_uri()
    profile = tmp_path / "profile"
    dom = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom", url],
                         capture_output=True, text=True, timeout=1800)
    assert dom.returncode == 0, dom.stderr[-2000:]
    parser = _Sections()
    parser.feed(dom.stdout)
    for key, entry in doc["sensors"].items():
        assert key in parser.sections, f"no section for {key}"
        if not entry["skipped"]:
            assert set(METRICS) <= parser.sections[key], key
    assert "Who wins on what" in dom.stdout
    shot = tmp_path / "shot.png"
    run = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--screenshot={shot}",
                          "--window-size=1280,2400", "--hide-scrollbars", url],
                         capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0 and shot.exists(), run.stderr[-2000:]
    import imageio.v3 as iio

    pixels = iio.imread(shot)[..., :3].reshape(-1, 3)
    not_white = (pixels < 235).any(axis=1).mean()
    colours = np.unique(pixels[:: max(1, pixels.shape[0] // 200_000)], axis=0).shape[0]
    assert not_white > 0.05 and colours > 200, (not_white, colours)


def test_cli_compare_json_and_table(tmp_path, capsys):
    code = main(["compare", "dilemma", "--sensors", "cmos,seed001-3seg", "--duration", "0.04", "--height", "32",
                 "--width", "48", "--out", str(tmp_path / "r"), "--json-file", str(tmp_path / "s.json"),
                 "--at", "0.005,0.02"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "PSNR dB" in out and "cmos" in out and "seed001-3seg" in out
    summary = json.loads((tmp_path / "s.json").read_text())
    assert set(summary["sensors"]) == {"cmos", "seed001-3seg"}
    assert json.loads(Path(summary["metrics"]).read_text())["instants_s"] == [0.005, 0.02]


@pytest.mark.parametrize("args, needle", [
    (["compare", "dilemma", "--sensors", "cmos,nosuch"], "--sensors"),
    (["compare", "dilemma", "--duration", "0"], "--duration"),
    (["compare", "dilemma", "--at", "0.5", "--duration", "0.01"], "instant"),
    (["compare", "dilemma", "--visibility-m", "50"], "--visibility-m"),
    (["compare", "nosuch-scene"], "scene"),
    (["compare", "dilemma", "--duration", "100"], "GB"),  # 33 GB of spike clip in memory
])
def test_compare_bad_input(tmp_path, capsys, monkeypatch, args, needle):
    # as on a first run (kernels not compiled yet): the compile notice must not come before the error
    monkeypatch.setattr("viform.cli.compare.kernels_cached", lambda: False)
    code = main([*args, "--out", str(tmp_path / "r")])
    _, err = capsys.readouterr()
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r" / "report.html").exists()


def test_compiled_kernels_are_recognised():
    """After one simulation the kernels' cache is found, so the 'compiling' notice is not printed again
    (it was printed on every run once the kernels moved to their own module)."""
    from viform.cli.compare import kernels_cached
    from viform.light.scenes import TranslatingScene
    from viform.sensors.spike import SpikeSensor

    SpikeSensor(threshold_electrons=100).capture(TranslatingScene(8, 16), 1e-3, seed=0)
    assert kernels_cached()
