"""One size convention: every command prints an image size as width × height (as cameras are quoted)."""

from __future__ import annotations

from click.testing import CliRunner

from viform._validate import size_text
from viform.cli import _load_commands, main
from viform.cli.app import cli

_load_commands()


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def test_size_text_is_width_by_height():
    assert size_text(250, 400) == "400×250 px"
    assert size_text(16, 24, "pixels") == "24×16 pixels"
    assert size_text(16, 24, "") == "24×16"


def test_commands_print_width_by_height(tmp_path, capsys):
    """A 16-row, 24-column stream reads 24×16 in simulate's summary, in a damaged file's error and in
    the sensor catalogue (SpikeOne: 400 columns, 250 rows)."""
    out = tmp_path / "a.dat"
    result = _run("simulate", "translating", "--height", 16, "--width", 24, "--duration", 0.002, "--out", out)
    assert result.exit_code == 0, result.output
    assert "24×16 pixels" in result.output and "16×24" not in result.output
    cut = tmp_path / "b.dat"
    cut.write_bytes(out.read_bytes()[:100])
    assert main(["info", str(cut), "--height", "16", "--width", "24"]) == 2
    err = capsys.readouterr().err
    assert "24×16 frames" in err and "16×24" not in err
    result = _run("sensors", "show", "spikeone")
    assert result.exit_code == 0 and "400×250 px (width × height)" in result.output
