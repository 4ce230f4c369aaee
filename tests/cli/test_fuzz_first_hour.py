"""Issue 27, a newcomer's first hour: bad inputs refused before any work, with the flag the user
typed, and nothing left behind; outputs that cannot be written refused first; every reading
command takes the same --key/--axes; reconstruct's defaults and what it says."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np
import pytest

from viform.cli import main
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes

#: A folder nobody can create files in (root included): an output path under it cannot be written.
UNWRITABLE = Path("/proc")

pytestmark = pytest.mark.skipif(not UNWRITABLE.is_dir(), reason="needs /proc (Linux) as an unwritable folder")


def run(args) -> tuple[int, str, str]:
    err, out = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.strip() and "%|" not in line
            and not line.startswith("compiling ")]


def everything_under(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.fixture()
def inputs(tmp_path, monkeypatch):
    """A small spike stream (.dat), a SpikingSIM-style .npz (arr_0, rows × columns × ticks), odd files."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    stream = SpikeStream(rng.random((200, 8, 16)) < 0.2, 40_000.0, 60.0)
    save_spikes(tmp_path / "s.dat", stream)
    np.savez(tmp_path / "sim.npz", arr_0=np.moveaxis(stream.read_ticks(0, 200), 0, -1).astype(np.uint8))
    (tmp_path / "random.vfc").write_bytes(rng.bytes(300))
    (tmp_path / "empty.vfc").write_bytes(b"")
    (tmp_path / "dir.dat").mkdir()
    return tmp_path


#: (arguments, the text the one error line must hold): each was accepted, or named the wrong thing.
BAD_INPUTS = [
    (["capture", "cmos", "dilemma", "--duration", "0.05", "--out", "o.npz", "--max-lux", "-3"], "--max-lux"),
    (["highspeed", "translating", "--scene-fps", "-1", "--out", "hs"], "--scene-fps"),
    (["reconstruct", "s.dat", "--window", "100", "--at", "0.002", "--out", "r.png"], "--window"),
    (["simulate", "translating", "--duration", "0.001", "--out", "x.dat", "--pixel-pitch-um", "-10"],
     "--pixel-pitch-um = -10"),
    (["lightcomm", "--led-cd", "-1"], "--led-cd"),
    (["gated", "--gate-m", "1e9"], "--gate-m"),
    (["highspeed", "translating", "--target", "300", "--out", "hs"], "--target"),
    (["simulate", "translating", "--out", "x.dat"], "--duration is required"),
    (["verify", "random.vfc"], "not a readable coded spike file"),
    (["info", "empty.vfc"], "is empty"),
    (["info", "dir.dat"], "is a folder, not a .dat file"),
    (["calibrate", "sim.npz"], "--key"),
    (["encode", "sim.npz", "o.vfc"], "--key"),
    (["reconstruct", "sim.npz", "--at", "0.001", "--out", "r.png"], "--key"),
    (["reconstruct", "sim.npz", "--key", "arr_0", "--at", "0.001", "--out", "r.png"], "--axes"),
]


def test_bad_inputs_are_refused_in_one_line_naming_the_flag(inputs):
    before = everything_under(inputs)
    failures = []
    for args, expected in BAD_INPUTS:
        rc, _, err = run(args)
        lines = error_lines(err)
        if rc != 2 or len(lines) != 1 or expected not in lines[0] or "Traceback" in err or "_m =" in err:
            failures.append((args, rc, err.strip()[:300]))
    assert failures == []
    assert everything_under(inputs) == before  # nothing left behind


def test_unwritable_outputs_are_refused_before_any_work(inputs):
    """Every output target is tried first: nothing runs and nothing is left (the demo used to run
    whole, then fail on --json-file and leave viform-demo/; simulate left o.npz)."""
    bad = UNWRITABLE / "viform-unwritable"
    cases = [
        (["demo", "--json-file", bad / "x.json"], "--json-file"),
        (["simulate", "translating", "--duration", "0.001", "--out", "o.npz", "--json-file", bad / "j.json"],
         "--json-file"),
        (["reconstruct", "s.dat", "--every", "50", "--out", "frames", "--video", bad / "v.mp4"], "--video"),
        (["compare", "dilemma", "--out", bad], "--out"),
        (["highspeed", "translating", "--out", bad], "--out"),
        (["highspeed-figures", "--out", bad], "--out"),
        (["dataset", ".", "--out", bad], "--out"),
        (["capture", "cmos", "dilemma", "--duration", "0.05", "--out", "o.npz", "--preview", bad / "p.png"],
         "--preview"),
        (["encode", "s.dat", bad / "o.vfc"], "DST"),
        (["calibrate", "s.dat", "--out", bad / "p.json"], "--out"),
    ]
    before = everything_under(inputs)
    failures = []
    for args, flag in cases:
        rc, _, err = run(args)
        lines = error_lines(err)
        if rc != 2 or len(lines) != 1 or flag not in lines[0] or "not writable" not in lines[0]:
            failures.append((args, rc, err.strip()[:300]))
    assert failures == []
    assert everything_under(inputs) == before


def test_every_reading_command_takes_key_and_axes(inputs):
    """SpikingSIM's arr_0 in rows × columns × ticks order, read by reconstruct, encode and calibrate."""
    foreign = ["--key", "arr_0", "--axes", "hwt"]
    rc, out, err = run(["reconstruct", "sim.npz", *foreign, "--at", "0.002", "--out", "r.png", "--json"])
    assert rc == 0, err
    rc, out, err = run(["encode", "sim.npz", "o.vfc", *foreign, "--json"])
    assert rc == 0, err
    assert json.loads(out)["spikes"] == int(np.load(inputs / "sim.npz")["arr_0"].sum())
    rc, out, err = run(["info", "sim.npz", *foreign, "--json"])
    assert rc == 0 and json.loads(out)["n_ticks"] == 200, err
    for command in ("info", "verify", "reconstruct", "encode", "calibrate"):
        rc, out, _ = run([command, "--help"])
        assert rc == 0 and all(flag in out for flag in ("--key", "--axes", "--height", "--width", "--no-flip"))


def test_reconstruct_says_when_no_pixel_is_measured_and_how_long_a_clip_needs(tmp_path):
    """Issue 27 item 2: a clip shorter than the pixels' intervals has no complete interval: no mean
    is printed from the bounds, and the clip length a measurement needs comes from the firing rate."""
    spikes = np.zeros((200, 8, 16), bool)
    spikes[10] = True  # every pixel fires once, at tick 10: no pixel has an interval holding tick 100
    path = save_spikes(tmp_path / "short.npz", SpikeStream(spikes, 40_000.0, 1000.0))
    rc, out, err = run(["reconstruct", path, "--method", "interval", "--at", "0.0025", "--out", tmp_path / "p.png",
                        "--json"])
    assert rc == 0, err
    summary = json.loads(out)
    assert summary["measured_fraction"] == [0.0] and summary["mean_firing_rate_per_tick"] == [None]
    # one spike per pixel in 200 ticks: a pixel fires every 200 ticks; two intervals are 400 ticks = 10 ms
    assert "every 200 ticks (5 ms)" in summary["no_measurement"]
    assert "at least 400 ticks (10 ms)" in summary["no_measurement"]
    rc, out, _ = run(["reconstruct", path, "--method", "interval", "--at", "0.0025", "--out", tmp_path / "p.png"])
    assert rc == 0 and "no pixel has a measurement" in out and "0.0%" in out


def test_reconstruct_defaults_to_multi_interval_and_names_its_display(inputs):
    rc, out, err = run(["reconstruct", "s.dat", "--at", "0.002", "--out", "r.png", "--json"])
    assert rc == 0, err
    summary = json.loads(out)
    assert summary["method"] == "multi-interval" and summary["display"] == "linear"
    assert "--display 8bit --scale 0.6" in summary["display_note"]
    rc, out, _ = run(["reconstruct", "s.dat", "--at", "0.002", "--out", "r.png", "--display", "8bit", "--scale",
                      "0.6"])
    assert rc == 0 and "the convention of published spike-camera numbers" in out


def test_info_names_each_quantity_once(inputs):
    """Issue 27 item 15: 'spikes rate', and two rows each of 'mean firing rate' and 'raw data rate'."""
    rc, out, err = run(["info", "s.dat"])
    assert rc == 0, err
    labels = [line.split(":")[0].strip() for line in out.splitlines()]
    assert len(labels) == len(set(labels)) and "spikes rate" not in labels
    rate = next(line for line in out.splitlines() if line.strip().startswith("mean firing rate"))
    assert "per tick" in rate and "Hz" in rate


def test_dr_shows_the_range_a_clip_can_show(inputs):
    """The SpikeOne-class sensor: 150 dB by the formula (intervals up to 812 s), 64 dB in a 40 ms clip."""
    rc, out, err = run(["dr", "--clock-hz", "40000", "--threshold-electrons", "16250", "--dark-current-e-per-s",
                        "20"])
    assert rc == 0, err
    assert "150.2 dB" in out and "64.1 dB in 40 ms" in out and "92.0 dB in 1 s" in out


def test_spike_capture_defaults_to_the_preset_resolution():
    """Issue 27 item 10: one rule with simulate --preset: a preset's resolution unless one is given."""
    from viform.cli.capture import default_resolution
    from viform.sensors.spike_presets import load_spike_preset

    preset = load_spike_preset("spikeone")
    assert default_resolution("spikeone") == (preset.height, preset.width) == (250, 400)
    assert default_resolution("spike") == (250, 400)  # simulate's default without a preset
    assert default_resolution("cmos") == (64, 128)  # compare's size


def test_spike_preview_shows_single_spikes(tmp_path):
    """Issue 27 item 1: a dim clip's preview was black (one spike = the log map's floor). Every pixel
    that fired in the preview's window is grey, every silent one black."""
    from viform.cli.capture import _spike_preview

    rng = np.random.default_rng(3)
    spikes = rng.random((400, 16, 24)) < 0.0005  # ~0.2 spikes a pixel over the clip: mostly single spikes
    stream = SpikeStream(spikes, 40_000.0, 16250.0)
    window_s = _spike_preview(tmp_path / "p.png", stream, float(spikes.mean()))
    assert window_s == pytest.approx(0.01)  # 8 spikes a pixel would need more: the whole clip is counted
    import imageio.v3 as iio

    image = iio.imread(tmp_path / "p.png")
    fired = np.repeat(np.repeat(spikes.any(axis=0), 2, axis=0), 2, axis=1)  # the preview doubles small images
    assert image[fired].min() > 0 and image[~fired].max() == 0
