"""viform lightcomm / viform display: output, JSON, figures, one-line errors."""

import json

from viform.cli import main


def test_lightcomm_cli_json_and_figures(tmp_path, capsys):
    js = tmp_path / "r.json"
    rc = main(["lightcomm", "--bitrate", "5000", "--distance-m", "20", "--ambient-lux", "0.5", "--bits", "200",
               "--json-file", str(js), "--out", str(tmp_path / "figs")])
    out = capsys.readouterr().out
    assert rc == 0
    assert "maximum error-free rate" in out
    r = json.loads(js.read_text())
    assert r["transmission"]["bit_errors"] == 0
    assert r["max_error_free"]["max_error_free_bps"] >= 5000
    assert (tmp_path / "figs" / "lightcomm_ber.png").stat().st_size > 0
    assert (tmp_path / "figs" / "lightcomm_raster.png").stat().st_size > 0


def test_lightcomm_cli_message(capsys):
    rc = main(["lightcomm", "--modulation", "ppm", "--bitrate", "4000", "--distance-m", "20", "--message", "hi!",
               "--no-max"])
    assert rc == 0
    assert "received 'hi!'" in capsys.readouterr().out


def test_lightcomm_cli_errors_are_one_line(capsys):
    for args, text in ((["--bitrate", "50000"], "above what the readout clock"),
                       (["--modulation", "qam"], "not known to the receiver"),
                       (["--message", ""], "empty"),
                       (["--distance-m", "-3"], "--distance-m")):
        rc = main(["lightcomm", *args, "--no-max"])
        err = capsys.readouterr().err
        assert rc == 2
        assert text in err
        assert err.count("\n") == 1 and "Traceback" not in err


def test_display_cli(tmp_path, capsys):
    js = tmp_path / "d.json"
    rc = main(["display", "--json-file", str(js)])
    out = capsys.readouterr().out
    assert rc == 0
    assert "hold 60 Hz" in out and "pass-through" in out
    r = json.loads(js.read_text())
    d = r["comparison"]["displays"]
    assert d["spike"]["tracked_edge_width_px"] < d["hold 120 Hz"]["tracked_edge_width_px"]
    assert r["passthrough"]["spike"]["latency_s"] < 1e-3


def test_unusable_outputs_are_refused_before_any_figure(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    for cmd in (["lightcomm", "--no-max"], ["display"]):
        rc = main([*cmd, "--out", str(tmp_path / "figs"), "--json-file", str(blocker / "r.json")])
        err = capsys.readouterr().err
        assert rc == 2 and "--json-file" in err and err.count("\n") == 1
        assert not (tmp_path / "figs").exists()


def test_display_json_flag_prints_json_to_stdout(capsys):
    """Bare --json prints the results as JSON on stdout (the project's one convention), no table."""
    rc = main(["display", "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    r = json.loads(out)
    assert r["comparison"]["displays"]["spike"]["tracked_edge_width_px"] < r["comparison"]["displays"]["hold 60 Hz"][
        "tracked_edge_width_px"]
