"""``viform characterize``: figures, JSON, and one-line errors."""

import json

import pytest

from viform.cli import main


def test_characterize_cmos_writes_pngs_and_json(tmp_path, capsys):
    rc = main(
        ["characterize", "cmos", "--out", str(tmp_path / "figs"), "--json-file", str(tmp_path / "r.json"), "--size",
         "32"]
    )
    assert rc == 0
    for name in ("ptc.png", "snr.png", "response.png"):
        assert (tmp_path / "figs" / name).stat().st_size > 1000
    data = json.loads((tmp_path / "r.json").read_text())
    e = data["emva1288"]
    assert abs(e["dynamic_range_db"] - e["expected"]["dynamic_range_db"]) < 1.0
    text = capsys.readouterr().out
    assert "dynamic range" in text and " dB" in text and "{" not in text  # a table with units


def test_characterize_bare_json_flag_prints_json(capsys):
    assert main(["characterize", "cmos", "--size", "8", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["sensor"] == "cmos" and "emva1288" in data


def test_response_figure_differs_per_sensor(tmp_path):
    """response.png used to be byte-identical for every sensor; now the characterized one is
    drawn bold (and named in the title), and curves start where SNR reaches 1."""
    import numpy as np

    from viform._io import save_figure
    from viform.report.response_plots import meaningful, response_figure

    lux = np.geomspace(0.1, 100, 20)
    out = np.minimum(lux / 10, 1.0)
    curves = {"a": {"lux": lux, "output": out, "snr": np.sqrt(lux * 10)},
              "b": {"lux": lux, "output": out / 2, "snr": np.sqrt(lux)}}
    save_figure(tmp_path / "a.png", response_figure(curves, "A", highlight="a"))
    save_figure(tmp_path / "b.png", response_figure(curves, "B", highlight="b"))
    assert (tmp_path / "a.png").read_bytes() != (tmp_path / "b.png").read_bytes()
    ok = meaningful(curves["a"])
    assert not ok[lux * 10 < 1].any()                     # SNR < 1: not drawn
    # stops before the first saturated point (output ≥ 99.5 % of the plateau, 10 lux): there
    # clipping collapses the variance and the SNR would jump up at the end of the curve
    assert ok.sum() == np.sum((lux * 10 >= 1) & (lux < 9.95))
    assert out[ok].max() < 0.995


def test_characterize_seed_preset_prints_seed_figures(tmp_path, capsys):
    rc = main(["characterize", "seed001-2seg", "--json-file", str(tmp_path / "s.json"), "--size", "16"])
    assert rc == 0
    data = json.loads((tmp_path / "s.json").read_text())
    assert abs(data["seed_comparison"]["model"]["extension_db"] - 10.88) < 1.0
    out = capsys.readouterr().out
    assert "range extension" in out and "extension_db" not in out  # readable rows, no Python keys
    assert "seed 0" not in out


def test_unknown_sensor_is_one_line_error(capsys):
    assert main(["characterize", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sensor" in err and "cmos" in err


@pytest.mark.parametrize("size", ["2", "9999"])
def test_bad_size(size, capsys):
    assert main(["characterize", "cmos", "--size", size]) == 2
    assert "--size" in capsys.readouterr().err


def test_unwritable_json_fails_before_any_figure_is_written(tmp_path, capsys):
    """A --json-file path under a regular file is refused up front: one line, exit 2, no PNGs."""
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("x")
    out = tmp_path / "figs"
    rc = main(["characterize", "cmos", "--size", "8", "--out", str(out), "--json-file", str(blocker / "r.json")])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--json-file" in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["not_a_dir"]


def test_out_under_a_file_is_refused(tmp_path, capsys):
    blocker = tmp_path / "f"
    blocker.write_text("x")
    assert main(["characterize", "cmos", "--size", "8", "--out", str(blocker / "figs")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err


def test_seed003_preset_reports_equation_gain(tmp_path):
    """The seed-003 comparison carries the measured gain and the closed form (55.5 dB)."""
    rc = main(["characterize", "seed003-overflow", "--json-file", str(tmp_path / "o.json"), "--size", "8"])
    assert rc == 0
    model = json.loads((tmp_path / "o.json").read_text())["seed_comparison"]["model"]
    assert model["dr_gain_equations_db"] == pytest.approx(55.53, abs=0.01)
    assert abs(model["dr_gain_db"] - model["dr_gain_equations_db"]) < 0.6  # grid step + PRNU


def test_set_changes_a_preset_parameter_by_name(capsys):
    """--set NAME=VALUE (issue 28): a designer changes one field and the EMVA figures follow it
    (read noise 3 → 12 e⁻: the measured dark noise follows, ±10 % from a 16×16 dark intercept)."""
    assert main(["characterize", "seed001-normal", "--size", "16", "--json", "--set", "read_noise_electrons=12"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["settings"] == {"read_noise_electrons": 12}
    e = data["emva1288"]
    assert e["expected"]["temporal_dark_noise_electrons"] == pytest.approx(12.0)
    assert e["temporal_dark_noise_electrons"] == pytest.approx(12.0, rel=0.15)


@pytest.mark.parametrize("setting, words", [("nope=1", "NAME one of"), ("read_noise_electrons=abc", "not a number"),
                                             ("read_noise_electrons=-1", "read_noise_electrons")])
def test_bad_set_is_one_line_error(setting, words, capsys):
    assert main(["characterize", "seed001-normal", "--size", "8", "--set", setting]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "Traceback" not in err[0]
