"""The sensor catalogue on the command line: ``viform sensors``, ``--set`` in every command that builds a
sensor, help texts that list the catalogue, names that changed meaning refused with their new name."""

import json
import re

import numpy as np
import pytest

from viform.cli import main
from viform.sensors.catalog import SENSORS, sensor_names


def run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_sensors_lists_the_catalogue_and_show_every_parameter(capsys):
    code, out, _ = run(["sensors"], capsys)
    assert code == 0 and all(name in out for name in SENSORS)
    code, out, _ = run(["sensors", "--json"], capsys)
    assert [r["name"] for r in json.loads(out)] == list(SENSORS)
    code, out, _ = run(["sensors", "show", "gated", "--json"], capsys)
    doc = json.loads(out)
    assert {p["name"] for p in doc["parameters"]} == set(SENSORS["gated"].parameters)
    laser = next(p for p in doc["parameters"] if p["name"] == "laser_peak_power_w")
    assert laser["unit"] == "W" and laser["default"] == 200.0 and laser["allowed"] == "a number > 0"
    code, out, _ = run(["sensors", "show", "highspeed"], capsys)
    assert code == 0 and "parasitic_light_sensitivity" in out and "a number in [0, 1]" in out
    code, _, err = run(["sensors", "show", "nope"], capsys)
    assert code == 2 and err.count("\n") == 1 and "spikeone" in err


@pytest.mark.parametrize("command, families", [
    (["capture"], ()), (["compare"], ()), (["sweep"], ()),
    (["characterize"], ("frame", "segmented", "overflow", "spike")), (["dataset"], ("spike",)),
    (["simulate"], ("spike",)),
])
def test_help_lists_every_sensor_from_the_catalogue(command, families, capsys):
    code, out, _ = run([*command, "--help"], capsys)
    assert code == 0
    text = " ".join(re.sub(r"-\n\s*", "-", out).split())  # a name the wrapper broke at its hyphen
    for name in sensor_names(*families):
        assert name in text, (command, name)
    assert "{sensors" not in text


@pytest.mark.parametrize("sensor, setting, check", [
    ("cmos", "exposure_s=0.002", lambda d: np.all(d["exposure_s"] == 0.002)),  # issue 33: exited 2
    ("seed003-4t", "exposure_s=0.01", lambda d: np.all(d["exposure_s"] == 0.01)),
    ("gated", "transfer_smear=true", lambda d: d["metadata"]["sensor"]["transfer_smear"] is True),
    ("gated", "bloom=true", lambda d: d["metadata"]["sensor"]["bloom"] is True),
    ("highspeed", "parasitic_light_sensitivity=0.01",
     lambda d: d["metadata"]["sensor"]["pixel_parameters"]["parasitic_light_sensitivity"] == 0.01),
])
def test_capture_set_reaches_every_sensor(sensor, setting, check, tmp_path, capsys):
    from viform.cli.capture import load_frame_stack

    scene = "night-road-fog" if sensor == "gated" else "translating"
    out = tmp_path / "c.npz"
    code, stdout, err = run(["capture", sensor, scene, "--duration", "0.04" if sensor != "highspeed" else "0.003",
                             "--height", "32", "--width", "48", "--out", str(out), "--set", setting, "--json"], capsys)
    assert code == 0, err
    assert json.loads(stdout)["settings"]
    assert check(load_frame_stack(out))


def test_capture_spike_set_threshold_level(tmp_path, capsys):
    from viform.stream.io import open_spikes

    out = tmp_path / "s.npz"
    code, _, err = run(["capture", "spikeone", "translating", "--duration", "0.002", "--height", "16", "--width",
                        "24", "--out", str(out), "--set", "threshold_level=3"], capsys)
    assert code == 0, err
    assert open_spikes(out).threshold_electrons == 5000.0  # (3 + 1) · 1 250 e⁻


@pytest.mark.parametrize("args, words", [
    (["capture", "cmos", "translating", "--set", "quantum_efficiency=2"],
     ["--set 'quantum_efficiency=2'", "e⁻/photon", "in (0, 1]"]),
    (["capture", "cmos", "translating", "--set", "exposure_s=0.5"], ["--set", "'exposure_s' = 0.5 s", "frame period"]),
    (["capture", "cmos", "translating", "--set", "nope=1"],
     ["'nope' is not a parameter of cmos", "'read_noise_electrons'"]),
    (["compare", "dilemma", "--sensors", "spike,cmos"], ["--sensors = 'spike'", "now 'spikeone'"]),
    (["sweep", "dilemma", "--sensor", "spike", "--workers", "0"], ["'spike'", "now 'spikeone'"]),
    (["sweep", "dilemma", "--sensor", "spikeone", "--vary", "spikeone:threshold_level=99", "--workers", "0"],
     ["threshold_level = 99", "[0, 15]"]),
    (["compare", "dilemma", "--sensors", "cmos", "--set", "foo=1"], ["'foo' is a parameter of none of cmos"]),
    (["characterize", "highspeed"], ["auto-exposure", "highspeed-figures"]),
    (["highspeed", "translating", "--duration", "0.01", "--frames", "5"], ["--duration and --frames"]),
    (["highspeed", "translating", "--target", "100", "--set", "target_gray=90"], ["--target", "give one"]),
])
def test_bad_settings_are_one_line_errors_naming_unit_and_range(args, words, tmp_path, capsys):
    args = [*args, "--out", str(tmp_path / "o" / ("x.npz" if args[0] == "capture" else "d"))] \
        if args[0] in ("capture", "compare", "sweep", "highspeed") else args
    if args[0] == "capture":
        args += ["--duration", "0.04"]
    code, _, err = run(args, capsys)
    assert code == 2 and err.count("\n") == 1, err
    for w in words:
        assert w in err, (w, err)


def test_compare_set_changes_one_sensor_or_every_sensor_that_has_it(tmp_path, capsys):
    code, out, err = run(["compare", "translating", "--sensors", "cmos,cmos-short", "--height", "32", "--width", "48",
                          "--duration", "0.04", "--set", "cmos:exposure_s=0.002", "--set", "read_noise_electrons=9",
                          "--out", str(tmp_path / "c"), "--json"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["settings"] == {"cmos": {"exposure_s": 0.002, "read_noise_electrons": 9.0},
                               "cmos-short": {"read_noise_electrons": 9.0}}
    saved = json.loads((tmp_path / "c" / "metrics.json").read_text())["sensors"]
    assert saved["cmos"]["metrics"]["time_resolution_s"] == 0.002 and saved["cmos-short"]["metrics"][
        "time_resolution_s"] == 1e-3


def test_highspeed_takes_a_duration(tmp_path, capsys):
    """Like every other command: --duration, every frame that ends inside it (1 666.7 fps: 0.006 s → 10)."""
    code, out, err = run(["highspeed", "translating", "--duration", "0.006", "--render", "32x18", "--steps", "none",
                          "--out", str(tmp_path / "hs"), "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["frames_captured"] == 10
