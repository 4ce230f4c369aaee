"""CLI of the spike camera core: simulate → info → reconstruct → demo, and the bad-input contract.

Bad input: one line on stderr naming the parameter, exit code 2, no traceback, no output file.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from viform.cli import main


def run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_simulate_info_reconstruct(tmp_path, capsys):
    spikes = tmp_path / "s.dat"
    code, out, err = run(["simulate", "moving-edge", "--duration", "0.005", "--out", str(spikes),
                          "--height", "16", "--width", "32", "--seed", "3", "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["n_ticks"] == 200
    assert spikes.stat().st_size == 200 * 16 * 32 // 8
    code, out, _ = run(["info", str(spikes), "--height", "16", "--width", "32", "--json"], capsys)
    summary = json.loads(out)
    assert summary["n_ticks"] == 200 and summary["height"] == 16
    assert summary["spike_count"] > 0
    assert summary["raw_data_rate_bit_per_s"] == 16 * 32 * 40_000
    folder = tmp_path / "img"
    for method in ("accumulation", "interval"):
        code, out, err = run(["reconstruct", str(spikes), "--method", method, "--at", "0.002,0.004",
                              "--height", "16", "--width", "32", "--out", str(folder), "--json"], capsys)
        assert code == 0, err
        assert json.loads(out)["ticks"] == [80, 160]
    light = np.load(folder / "light.npz")
    assert light["spikes_per_s"].shape == (2, 16, 32)
    assert len(list(folder.glob("*.png"))) == 4


def test_zarr_output_keeps_sensor_metadata_so_lux_comes_back(tmp_path, capsys):
    store = tmp_path / "s.zarr"
    code, _, err = run(["simulate", "hdr", "--duration", "0.002", "--out", str(store), "--height", "8",
                        "--width", "64", "-q", "400"], capsys)
    assert code == 0, err
    code, out, err = run(["reconstruct", str(store), "--method", "accumulation", "--at", "0.0019",
                          "--window", "0.0015", "--out", str(tmp_path / "r")], capsys)
    assert code == 0, err
    light = np.load(tmp_path / "r" / "light.npz")
    assert "lux" in light and np.all(np.isfinite(light["lux"]))


@pytest.mark.parametrize("args,needle", [
    (["simulate", "translating", "--duration", "0.001", "--out", "{tmp}/x.dat", "-q", "0"], "--threshold-electrons"),
    (["simulate", "translating", "--duration", "0.001", "--out", "{tmp}/x.dat", "--clock-hz", "-5"], "--clock-hz"),
    (["simulate", "translating", "--duration", "-1", "--out", "{tmp}/x.dat"], "--duration"),
    (["simulate", "no-such-scene", "--duration", "0.001", "--out", "{tmp}/x.dat"], "built-in scene"),
    (["simulate", "translating", "--duration", "0.001", "--out", "{tmp}/x.txt"], "suffix"),
    (["simulate", "{tmp}/broken.mp4", "--duration", "0.001", "--out", "{tmp}/x.dat", "--frame-rate-hz", "30"],
     "could not be read"),
    (["info", "{tmp}/good.dat"], "height and width are required"),
    (["info", "{tmp}/good.dat", "--height", "5", "--width", "8"], "not a whole number"),
    (["reconstruct", "{tmp}/good.dat", "--method", "interval", "--at", "9", "--height", "4", "--width", "8",
      "--out", "{tmp}/x.png"], "outside the stream"),
    (["reconstruct", "{tmp}/good.dat", "--method", "interval", "--at", "abc", "--height", "4", "--width", "8",
      "--out", "{tmp}/x.png"], "--at"),
    (["reconstruct", "{tmp}/good.dat", "--method", "interval", "--at", "0", "--height", "4", "--width", "8",
      "--out", "{tmp}/x.jpg"], "--out"),
    (["reconstruct", "{tmp}/good.dat", "--method", "accumulation", "--display", "seed", "--at", "0",
      "--height", "4", "--width", "8", "--out", "{tmp}/x.png"], "--display"),
    (["info", "{tmp}/good.dat", "--height", "4", "--width", "8", "--clock-hz", "0"], "--clock-hz"),
    (["info", "{tmp}/broken.mp4"], "unknown spike file type"),
    (["info", "{tmp}/text.npz"], "not a .npz"),
    (["simulate", "translating", "--duration", "0.001", "--out", "{tmp}/file.dat/x.dat"], "--out"),
])
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, capsys, args, needle):
    from viform.stream.container import SpikeStream
    from viform.stream.dat import write_dat

    write_dat(tmp_path / "good.dat", SpikeStream(np.ones((3, 4, 8), bool), 40_000.0), sidecar=False)
    (tmp_path / "broken.mp4").write_bytes(b"garbage")
    (tmp_path / "text.npz").write_text("not an archive")
    (tmp_path / "file.dat").write_bytes(b"")  # a file where a folder is needed
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    code, out, err = run(args, capsys)
    assert code == 2
    assert needle in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "x.dat").exists() and not (tmp_path / "x.png").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".x.")]  # no temp file left


def test_negative_lux_image_is_refused(tmp_path, capsys):
    np.save(tmp_path / "bad.npy", np.array([[1.0, -1.0]]))
    from viform._validate import ViformError
    from viform.light.scenes import StillScene

    with pytest.raises(ViformError, match="negative"):
        StillScene(np.load(tmp_path / "bad.npy"))


def test_interrupted_write_leaves_no_file(tmp_path):
    """A failure part-way through writing a stream (as Ctrl-C would) leaves nothing under the name."""
    from viform.stream.container import SpikeStream
    from viform.stream.io import save_spikes

    class Exploding(SpikeStream):
        def iter_blocks(self, block_ticks=1024, start=0, stop=None):
            yield 0, self.spikes[:1]
            raise KeyboardInterrupt

    stream = Exploding(np.ones((4, 4, 8), bool), 40_000.0)
    for name in ("a.dat", "a.zarr"):
        with pytest.raises(KeyboardInterrupt):
            save_spikes(tmp_path / name, stream, block_ticks=1)
    assert list(tmp_path.iterdir()) == []


def test_demo_runs_and_reports_scores(tmp_path):
    """The README's main command, in a subprocess as a user runs it (short here): the comparison
    of every sensor on the dilemma scene, with the spike camera's images scored against the truth."""
    result = subprocess.run([sys.executable, "-m", "viform.cli", "demo", "--out", str(tmp_path / "d"),
                             "--duration", "0.01"], capture_output=True, text=True, timeout=1800)
    assert result.returncode == 0, result.stderr
    doc = json.loads((tmp_path / "d" / "metrics.json").read_text())
    for key in ("spikeone-accumulation", "spikeone-interval"):
        metrics = doc["sensors"][key]["metrics"]
        assert np.isfinite(metrics["psnr_log_db"]) and np.isfinite(metrics["ssim_log"])
    assert doc["sensors"]["spikeone-interval"]["metrics"]["psnr_log_db"] > 10
    assert (tmp_path / "d" / "report.html").stat().st_size > 0
    assert "PSNR dB" in result.stdout
    # it ends with the designer's answer from a sweep of settings (issue 23)
    assert "Which setting would meet the scene's demands" in result.stdout.split("PSNR dB")[-1]
    swept = json.loads((tmp_path / "d" / "sweep" / "sweep.json").read_text())
    assert swept["answer"]["sentences"][0] in result.stdout
    assert {p["sensor"] for p in swept["points"]} == {"spikeone", "cmos", "seed003-overflow"}


def test_help_of_every_command(capsys):
    for command in ("simulate", "reconstruct", "info", "demo"):
        with pytest.raises(SystemExit) as exc:
            from viform.cli.app import cli

            cli.main([command, "--help"], prog_name="viform")
        assert exc.value.code == 0
