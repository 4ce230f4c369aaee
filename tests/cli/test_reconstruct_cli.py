"""viform reconstruct: alignment, every method, whole-stream video and light.npz, bad input."""

import json

import numpy as np
import pytest

from viform.cli import main
from viform.light.scenes import TranslatingScene
from viform.sensors.spike import SpikeSensor
from viform.stream.io import save_spikes


def run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    sensor = SpikeSensor(threshold_electrons=1000.0)
    scene = TranslatingScene(32, 48, velocity_px_per_s=(2000.0, 0.0), min_lux=5.0, max_lux=50.0, period_px=16)
    path = tmp_path_factory.mktemp("clip") / "clip.zarr"
    save_spikes(path, sensor.capture(scene, 200 / 40_000, seed=1))
    return path


@pytest.mark.parametrize("method", ["accumulation", "interval", "multi-interval", "motion"])
def test_whole_stream_every_method(clip, tmp_path, capsys, method):
    out = tmp_path / "frames"
    video = tmp_path / "movie.mp4"
    code, stdout, err = run(["reconstruct", str(clip), "--method", method, "--every", "50", "--out", str(out),
                             "--video", str(video), "--json"], capsys)
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["ticks"] == [25, 75, 125, 175]
    light = np.load(out / "light.npz")
    assert light["lux"].shape == (4, 32, 48) and np.all(light["lux"] >= 0)
    assert np.all(np.isfinite(light["lux"])) and light["ticks"].tolist() == [25, 75, 125, 175]
    # the scene's light is 5–50 lux: every method's frame mean lies in it
    assert np.all((light["lux"].mean(axis=(1, 2)) > 5) & (light["lux"].mean(axis=(1, 2)) < 50))
    assert video.stat().st_size > 0 and len(list(out.glob("*.png"))) == 4


def test_align_moves_the_window(clip, tmp_path, capsys):
    results = {}
    for align in ("centre", "end", "start"):
        code, stdout, err = run(["reconstruct", str(clip), "--method", "accumulation", "--at", "0.0025",
                                 "--align", align, "--out", str(tmp_path / f"{align}.png"), "--json"], capsys)
        assert code == 0, err
        results[align] = json.loads(stdout)
    assert results["centre"]["align"] == "centre" and results["centre"]["window_ticks"] == 41
    images = {a: (tmp_path / f"{a}.png").read_bytes() for a in results}
    assert images["centre"] != images["end"] != images["start"]


def test_table_and_json_file(clip, tmp_path, capsys):
    code, stdout, err = run(["reconstruct", str(clip), "--method", "interval", "--at", "0.001,0.002",
                             "--out", str(tmp_path / "f"), "--json-file", str(tmp_path / "s.json")], capsys)
    assert code == 0, err
    assert "rate (/tick)" in stdout and "mean (lux)" in stdout
    assert json.loads((tmp_path / "s.json").read_text())["ticks"] == [40, 80]


@pytest.mark.parametrize("args, flag", [
    (["--every", "0"], "--every"),
    (["--at", "0.001", "--every", "5"], "--every"),
    (["--at", "0.001", "--video", "x.avi"], "--video"),
    (["--at", "0.001", "--fps", "0", "--video", "x.mp4"], "--fps"),
    (["--at", "0.001", "--spikes-per-side", "0"], "--spikes-per-side"),
    (["--at", "0.002,0.001"], "--at"),
])
def test_bad_input_is_one_line_naming_the_flag(clip, tmp_path, capsys, args, flag):
    code, _, err = run(["reconstruct", str(clip), "--method", "multi-interval", "--out", str(tmp_path / "o"), *args],
                       capsys)
    assert code == 2 and flag in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "light.npz").exists()


def test_json_file_folder_is_created_like_out(clip, tmp_path, capsys):
    """--json-file into a folder that does not exist creates it, as --out does (one rule for every command)."""
    code, _, err = run(["reconstruct", str(clip), "--method", "accumulation", "--at", "0.001", "--out",
                        str(tmp_path / "o.png"), "--json-file", str(tmp_path / "no" / "s.json")], capsys)
    assert code == 0, err
    assert json.loads((tmp_path / "no" / "s.json").read_text())["ticks"] == [40]
    assert (tmp_path / "o.png").exists()


def test_display_255_tau_and_its_old_name(clip, tmp_path, capsys):
    """--display 255-tau (grey 255 − τ) draws what the old, still accepted, name 'seed' drew."""
    import imageio.v3 as iio

    images = []
    for name in ("255-tau", "seed"):
        png = tmp_path / f"{name}.png"
        code, _, err = run(["reconstruct", str(clip), "--method", "interval", "--at", "0.002", "--display", name,
                            "--out", str(png)], capsys)
        assert code == 0, err
        images.append(iio.imread(png))
    assert np.array_equal(images[0], images[1]) and images[0].std() > 0
    code, _, err = run(["reconstruct", str(clip), "--method", "accumulation", "--at", "0.002", "--display",
                        "255-tau", "--out", str(tmp_path / "x.png")], capsys)
    assert code == 2 and "--display" in err
    code, text, _ = run(["reconstruct", "--help"], capsys)
    assert "255-tau" in text and "seed" not in text and "TFP" not in text


def test_at_alone_writes_a_png_in_the_working_folder(clip, tmp_path, capsys, monkeypatch):
    """The README's own form, `viform reconstruct F --at T`, writes STEM_METHOD_Ts.png where the user is."""
    import imageio.v3 as iio

    monkeypatch.chdir(tmp_path)
    code, stdout, err = run(["reconstruct", str(clip), "--at", "0.002"], capsys)
    assert code == 0, err
    png = tmp_path / "clip_multi-interval_0.002000s.png"
    assert png.is_file() and iio.imread(png).shape == (32, 48)
    assert str(png.name) in stdout
    # several instants: one folder named after the input, with light.npz
    code, _, err = run(["reconstruct", str(clip), "--at", "0.001,0.003", "--method", "interval"], capsys)
    assert code == 0, err
    assert np.load(tmp_path / "clip_interval" / "light.npz")["ticks"].tolist() == [40, 120]


def test_one_definition_of_white(clip, tmp_path, capsys):
    """The table names one white level, with its lux and where it comes from (not two definitions)."""
    code, stdout, err = run(["reconstruct", str(clip), "--every", "40", "--out", str(tmp_path / "f")], capsys)
    assert code == 0, err
    assert stdout.count("white =") == 1 and stdout.count("99.9th percentile") == 1, stdout
    assert "lux" in stdout.split("white =", 1)[1].splitlines()[0]


@pytest.mark.parametrize("case", ["nan", "late", "empty", "truncated", "png"])
def test_inputs_are_checked_before_outputs(clip, tmp_path, capsys, case, monkeypatch):
    """A bad instant or a bad file is named as such, whether or not an output was given."""
    monkeypatch.chdir(tmp_path)
    path, at, expect = str(clip), "0.002", None
    if case == "nan":
        at, expect = "nan", "--at"
    elif case == "late":
        at, expect = "5", "--at"
    elif case == "empty":
        (tmp_path / "e.dat").write_bytes(b"")
        path, expect = str(tmp_path / "e.dat"), "e.dat"
    elif case == "truncated":
        (tmp_path / "t.dat").write_bytes(b"\x00" * 1001)
        path, expect = str(tmp_path / "t.dat"), "t.dat"
    else:
        import imageio.v3 as iio

        iio.imwrite(tmp_path / "p.png", np.zeros((8, 8), np.uint8))
        path, expect = str(tmp_path / "p.png"), "p.png"
    extra = ["--height", "8", "--width", "8"] if case in ("empty", "truncated") else []
    code, _, err = run(["reconstruct", path, "--at", at, *extra], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "nothing to write" not in err and expect in err, err
    assert not list(tmp_path.glob("*_multi-interval*"))
