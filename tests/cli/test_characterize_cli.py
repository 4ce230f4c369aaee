"""``viform characterize``: figures, JSON, and one-line errors."""

import json

import pytest

from viform.cli import main


def test_characterize_cmos_writes_pngs_and_json(tmp_path, capsys):
    rc = main(
        ["characterize", "cmos", "--out", str(tmp_path / "figs"), "--json", str(tmp_path / "r.json"), "--size", "32"]
    )
    assert rc == 0
    for name in ("ptc.png", "snr.png", "response.png"):
        assert (tmp_path / "figs" / name).stat().st_size > 1000
    data = json.loads((tmp_path / "r.json").read_text())
    e = data["emva1288"]
    assert abs(e["dynamic_range_db"] - e["expected"]["dynamic_range_db"]) < 1.0
    assert "DR" in capsys.readouterr().out


def test_characterize_seed_preset_prints_seed_figures(tmp_path, capsys):
    rc = main(["characterize", "seed001-2seg", "--json", str(tmp_path / "s.json"), "--size", "16"])
    assert rc == 0
    data = json.loads((tmp_path / "s.json").read_text())
    assert abs(data["seed_comparison"]["model"]["extension_db"] - 10.88) < 1.0
    assert "extension_db" in capsys.readouterr().out


def test_unknown_sensor_is_one_line_error(capsys):
    assert main(["characterize", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sensor" in err and "cmos" in err


@pytest.mark.parametrize("size", ["2", "9999"])
def test_bad_size(size, capsys):
    assert main(["characterize", "cmos", "--size", size]) == 2
    assert "--size" in capsys.readouterr().err
