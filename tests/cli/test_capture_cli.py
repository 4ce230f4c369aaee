"""``viform capture``: every sensor preset shoots a scene and saves its output with the exposure windows."""

import json

import numpy as np
import pytest

from viform.cli import main
from viform.cli.capture import capture_sensor_names, is_spike, load_frame_stack


def run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_every_sensor_captures(tmp_path, capsys):
    """Each preset writes its output; frames carry start times, exposures, units and the sensor."""
    for name in capture_sensor_names():
        scene = "night-road-fog" if name == "gated" else "dilemma"
        out = tmp_path / (f"{name}.npz")
        code, stdout, err = run(["capture", name, scene, "--duration", "0.004", "--out", str(out),
                                 "--height", "32", "--width", "48", "--json"], capsys)
        assert code == 0, (name, err)
        summary = json.loads(stdout)
        assert out.exists()
        if is_spike(name):
            from viform.stream.io import open_spikes

            stream = open_spikes(out)
            assert stream.shape[1:] == (32, 48) and stream.n_ticks == summary["n_ticks"] > 0
            continue
        data = load_frame_stack(out)
        n = len(data["frames"])
        assert n == summary["frames"] >= 1 and data["frames"].shape[1:] == (32, 48)
        assert data["start_times_s"].shape == data["exposure_s"].shape == (n,)
        assert np.all(data["exposure_s"] > 0) and data["units"]
        assert "sensor" in data["metadata"] and "scene" in data["metadata"]
        if name == "highspeed":  # the camera's own output: equalized frames, one in N over the link
            with np.load(out) as z:
                sent = z["output_frame_indices"]
                assert z["output_frames"].shape == (sent.size, 32, 48) and np.all(np.diff(sent) > 0)
                assert z["auto_exposure_cycles"].shape == (n,)


def _led_on_fraction(path, scene):
    """Per frame: the LED's measured on-fraction (from DN, through the linear model) and the exact one."""
    from viform.light.dilemma import pwm_on_time_s
    from viform.light.radiometry import PixelOptics

    data = load_frame_stack(path)
    meta = data["metadata"]["sensor"]
    gain, black = meta["system_gain_dn_per_e"], meta["black_offset_dn"]
    e_per_lux_s = PixelOptics(**meta["optics"]).electrons_per_lux_second
    measured, expected = [], []
    for frame, t0, t in zip(data["frames"], data["start_times_s"], data["exposure_s"], strict=True):
        electrons = (frame[scene.led].astype(float).mean() - black) / gain - meta["dark_current_e_per_s"] * t
        lux = electrons / (e_per_lux_s * t)
        measured.append((lux - scene.led_off_lux) / (scene.led_on_lux - scene.led_off_lux))
        expected.append((pwm_on_time_s(t0 + t, 90.0, 0.25) - pwm_on_time_s(t0, 90.0, 0.25)) / t)
    return np.array(measured), np.array(expected)


def test_each_frame_integrates_its_own_window(tmp_path, capsys):
    """The PWM LED's level in each frame follows the LED's on-time in that frame's own exposure window.

    seed001-normal: 130 µs at 60 fps, so frames alternate between the LED's on and off phases
    (1/60 s = 1.5 PWM periods). The LED gives ~190 e⁻ a pixel when on: shot + read noise ≈ 14 e⁻,
    2.5 % of the swing on the 9-pixel LED mean, so 0.1 is a 4σ tolerance.
    cmos-short: 30 fps is exactly 3 PWM periods, so every frame sees the same phase (the
    stroboscopic lock of a frame camera on a 90 Hz LED) — the same on-fraction each frame.
    """
    from viform.light.dilemma import DilemmaScene

    scene = DilemmaScene(32, 48)
    for name, n in (("seed001-normal", 6), ("cmos-short", 3)):
        out = tmp_path / f"{name}.npz"
        code, _, err = run(["capture", name, "dilemma", "--duration", "0.1", "--out", str(out),
                            "--height", "32", "--width", "48"], capsys)
        assert code == 0, err
        measured, expected = _led_on_fraction(out, scene)
        assert measured.size == n
        np.testing.assert_allclose(measured, expected, atol=0.1)
        if name == "seed001-normal":
            np.testing.assert_allclose(expected, [1, 0, 1, 0, 1, 0], atol=1e-9)
        else:
            np.testing.assert_allclose(expected, expected[0], atol=1e-9)


def test_zarr_frames_and_previews(tmp_path, capsys):
    out, png, mp4 = tmp_path / "f.zarr", tmp_path / "p.png", tmp_path / "p.mp4"
    code, _, err = run(["capture", "cmos", "dilemma", "--duration", "0.07", "--out", str(out), "--preview",
                        str(png), "--height", "32", "--width", "48"], capsys)
    assert code == 0, err
    data = load_frame_stack(out)
    assert data["frames"].shape == (2, 32, 48) and data["units"].startswith("DN")
    np.testing.assert_allclose(data["start_times_s"], [0, 1 / 30])
    import imageio.v3 as iio

    image = iio.imread(png)
    assert image.shape == (64, 96) and image.std() > 5  # doubled pixels, not a flat frame
    code, _, err = run(["capture", "spike", "dilemma", "--duration", "0.003", "--out", str(tmp_path / "s.dat"),
                        "--preview", str(mp4), "--height", "32", "--width", "48"], capsys)
    assert code == 0, err
    assert iio.improps(mp4).shape[0] >= 10


@pytest.mark.parametrize("args, needle", [
    (["capture", "nosuch", "dilemma", "--duration", "0.01", "--out", "{t}/a.npz"], "SENSOR"),
    (["capture", "gated", "dilemma", "--duration", "0.01", "--out", "{t}/a.npz"], "SCENE"),
    (["capture", "cmos", "dilemma", "--duration", "0.01", "--out", "{t}/a.dat"], "--out"),
    (["capture", "spike", "dilemma", "--duration", "0.01", "--out", "{t}/a.png"], "--out"),
    (["capture", "cmos", "dilemma", "--duration", "-1", "--out", "{t}/a.npz"], "--duration"),
    (["capture", "highspeed", "dilemma", "--duration", "100", "--out", "{t}/a.npz"], "GB"),  # 11 GB of frames
    (["capture", "cmos", "dilemma", "--duration", "0.01", "--out", "{t}/a.npz", "--preview", "{t}/p.jpg"],
     "--preview"),
    # 33 × 49 pixels do not fill whole bytes: a .dat is refused before anything is simulated or written
    (["capture", "spike", "dilemma", "--duration", "0.001", "--out", "{t}/a.dat", "--height", "33", "--width", "49"],
     "--height = 33 and --width = 49"),
    # 100 ticks of 250 × 400 pixels = 1.25 MB on a disk with 1 MB free (patched below)
    (["capture", "spike", "dilemma", "--duration", "0.0025", "--out", "{t}/a.dat"], "disk space"),
    # hours of simulation from a mistyped duration: refused with the estimate unless --force, as by simulate
    (["capture", "spikeone", "dilemma", "--duration", "10", "--out", "{t}/a.npz"], "--force"),
])
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, capsys, monkeypatch, args, needle):
    # as on a first run (kernels not compiled yet): the compile notice must not come before the error
    monkeypatch.setattr("viform.cli.compare.kernels_cached", lambda: False)
    if needle == "disk space":  # a disk with 1 MB free: the 1.25 MB .dat cannot fit
        import shutil
        from collections import namedtuple

        monkeypatch.setattr(shutil, "disk_usage", lambda _: namedtuple("u", "total used free")(10**9, 10**9, 10**6))
    code, _, err = run([a.replace("{t}", str(tmp_path)) for a in args], capsys)
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_set_changes_a_frame_preset_parameter(tmp_path, capsys):
    """--set dark_current_e_per_s adds dark·exposure electrons per pixel: the mean rises by that × gain."""
    from viform.sensors.catalog import make_sensor

    outs = {}
    for label, extra in (("plain", []), ("dark", ["--set", "dark_current_e_per_s=5000"])):
        outs[label] = tmp_path / f"{label}.npz"
        code, _, err = run(["capture", "cmos", "translating", "--duration", "0.04", "--out", str(outs[label]),
                            "--seed", "3", *extra], capsys)
        assert code == 0, err
    sensor = make_sensor("cmos")
    p = sensor.parameters
    expected = (5000 - p.dark_current_e_per_s) * sensor.exposure_s * p.system_gain_dn_per_e
    plain, dark = (load_frame_stack(outs[k])["frames"].astype(float) for k in ("plain", "dark"))
    assert dark.max() < p.max_dn  # nothing clipped
    # Poisson noise of 50 e- over 8,192 pixels: the mean is known to about 0.1 e-
    assert dark.mean() - plain.mean() == pytest.approx(expected, rel=0.05)
    code, _, err = run(["capture", "spike", "translating", "--duration", "0.001", "--out", str(tmp_path / "s.npz"),
                        "--set", "x=1"], capsys)
    assert code == 2 and "--set" in err and not (tmp_path / "s.npz").exists()
