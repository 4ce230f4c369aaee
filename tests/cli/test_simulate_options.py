"""viform simulate: --preset, --threshold-level and the noise-model options.

Bad input: one line naming the flag, exit code 2, no output file.
"""

import json

import pytest

from viform.cli import main
from viform.sensors.spike_presets import threshold_level_electrons
from viform.stream.io import open_spikes


def run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_preset_and_threshold_level(tmp_path, capsys):
    out = tmp_path / "s.dat"
    code, text, err = run(["simulate", "hdr", "--preset", "spikeone", "--threshold-level", "2", "--height", "8",
                           "--width", "10", "--duration", "0.001", "--dead-time-s", "1e-6", "--out", str(out),
                           "--json"], capsys)
    assert code == 0, err
    summary = json.loads(text)
    assert summary["preset"] == "spikeone"
    assert summary["threshold_electrons"] == threshold_level_electrons(2)
    assert summary["clock_hz"] == 40_000.0 and summary["n_ticks"] == 40
    assert summary["gain_spread_fraction"] > 0  # the chip preset's PRNU
    assert summary["dead_time_s"] == 1e-6
    stream = open_spikes(out)
    assert stream.shape == (40, 8, 10)


def test_preset_sets_the_resolution_and_options_override_it(tmp_path, capsys):
    out = tmp_path / "s.npz"
    code, text, err = run(["simulate", "moving-edge", "--preset", "spiketwo", "--duration", "0.0002",
                           "--clock-hz", "40000", "-q", "300", "--out", str(out), "--json"], capsys)
    assert code == 0, err
    summary = json.loads(text)
    assert (summary["height"], summary["width"]) == (1000, 1000)
    assert summary["clock_hz"] == 40_000.0 and summary["threshold_electrons"] == 300.0


@pytest.mark.parametrize("args,flag", [
    (["--threshold-level", "16"], "--threshold-level"),
    (["--threshold-level", "3", "-q", "50"], "--threshold-level"),
    (["--preset", "no-such-chip"], "--preset"),
    (["--gain-spread", "1.5"], "--gain-spread"),
    (["--dead-time-s", "-1"], "--dead-time-s"),
    (["--hot-pixel-fraction", "2"], "--hot-pixel-fraction"),
])
def test_bad_options_name_their_flag(tmp_path, capsys, args, flag):
    out = tmp_path / "x.dat"
    code, _, err = run(["simulate", "hdr", "--duration", "0.001", "--height", "4", "--width", "4", "--out", str(out),
                        *args], capsys)
    assert code == 2
    assert flag in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_preset_file_with_a_bad_key_is_named(tmp_path, capsys):
    preset = tmp_path / "p.json"
    preset.write_text(json.dumps({"format": "viform-spike-preset", "version": 1, "name": "x", "height": 4,
                                  "width": 4, "sensor": {"threshold_electronz": 10}}))
    code, _, err = run(["simulate", "hdr", "--duration", "0.001", "--preset", str(preset),
                        "--out", str(tmp_path / "x.dat")], capsys)
    assert code == 2
    assert "threshold_electronz" in err


@pytest.mark.parametrize("scene", ["moving-edge", "translating"])
def test_metadata_records_the_scene_name_given(tmp_path, capsys, scene):
    """moving-edge is a translating edge, but the file says what the user asked for."""
    out = tmp_path / "s.dat"
    code, _, err = run(["simulate", scene, "--duration", "0.0005", "--height", "4", "--width", "8", "--out",
                        str(out)], capsys)
    assert code == 0, err
    assert open_spikes(out).metadata["scene"]["name"] == scene
    code, text, _ = run(["info", str(out), "--json"], capsys)
    assert code == 0 and json.loads(text)["scene"] == scene
