"""``viform gated``: report, JSON, figures, one-line errors."""

import json

from viform.cli import main


def test_gated_cli_writes_json_and_figures(tmp_path, capsys):
    out = tmp_path / "out"
    js = tmp_path / "r.json"
    assert main(["gated", "--pulses", "20", "--out", str(out), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert "seed: 15–20" in text and "seed: 70–90" in text
    data = json.loads(js.read_text())
    acc = {t["range_m"]: t["visible"] for t in data["modes"]["accumulate"]["targets"]}
    assert acc == {50.0: False, 100.0: False, 200.0: True, 300.0: True}
    assert {p.name for p in out.glob("*.png")} == {
        "range_intensity.png",
        "fog_gated_vs_ungated.png",
        "modes.png",
        "cnr.png",
    }


def test_gated_cli_bad_input_one_line(capsys, tmp_path):
    for args, name in (
        (["--visibility-m", "-5"], "visibility_m"),
        (["--gate-m", "-1"], "gate_m"),
        (["--pulses", "1000"], "pulses"),
        (["--gate-m", "20000"], "gate_range_m"),
    ):
        out, js = tmp_path / "figs", tmp_path / "r.json"
        assert main(["gated", *args, "--out", str(out), "--json", str(js)]) == 2
        err = capsys.readouterr().err.strip()
        assert name in err and "\n" not in err and err.startswith("viform: error:")
        assert not out.exists() and not js.exists()  # no partial output
