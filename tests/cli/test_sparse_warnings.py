"""Every command that estimates from spikes warns, in one line with the figure, when the stream is too sparse."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from viform.cli import _load_commands
from viform.cli.app import cli

_load_commands()


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def sparse(tmp_path_factory):
    """The translating scene at the SpikeOne preset: ≈ 0.001 spikes per pixel-tick."""
    folder = tmp_path_factory.mktemp("sparse")
    out = folder / "s.dat"
    result = _run("simulate", "translating", "--preset", "spikeone", "--height", 32, "--width", 48, "--duration",
                  0.012, "--out", out, "--seed", 1)
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def dense(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dense")
    out = folder / "d.dat"
    result = _run("simulate", "multi-object", "--height", 32, "--width", 48, "--duration", 0.012, "--out", out,
                  "-q", 100, "--seed", 1)
    assert result.exit_code == 0, result.output
    return out


def _warning(result):
    lines = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    assert len(lines) == 1, result.stderr
    assert "spikes per pixel-tick" in lines[0] and "needed" in lines[0]
    return lines[0]


@pytest.mark.parametrize("command", [
    ["flow", "--at", 0.004, "--dt", 0.001, "--out", "{tmp}/f"],
    ["track", "--every", 40],
    ["reconstruct", "--at", 0.006, "--out", "{tmp}/r"],
    ["reconstruct", "--method", "accumulation", "--at", 0.006, "--out", "{tmp}/a"],
])
def test_sparse_stream_is_said_with_its_figure(sparse, dense, tmp_path, command):
    args = [str(a).replace("{tmp}", str(tmp_path)) for a in command]
    result = _run(args[0], sparse, *args[1:])
    assert result.exit_code == 0, result.output
    line = _warning(result)
    assert "0.001" in line or "0.0009" in line or "0.0008" in line or "0.0011" in line, line
    assert "lower the threshold" in line
    # a dense stream (Q = 100, multi-object) draws no warning
    ok = _run(args[0], dense, *[a.replace(str(tmp_path), str(tmp_path / "dense")) for a in args[1:]])
    assert ok.exit_code == 0, ok.output
    assert "warning:" not in ok.stderr


def test_flow_json_keeps_stdout_clean_and_records_the_support(sparse, tmp_path):
    result = _run("flow", sparse, "--at", 0.004, "--dt", 0.001, "--out", tmp_path / "f", "--json")
    summary = json.loads(result.stdout)
    assert summary["support"]["enough"] is False and summary["warning"].startswith("warning:")


def test_sweep_points_on_too_few_spikes_are_said(tmp_path):
    result = _run("sweep", "translating", "--sensor", "spikeone", "--height", 32, "--width", 48, "--duration", 0.012,
                  "--at", "0.004,0.008", "--workers", 0, "--no-progress", "--out", tmp_path / "sw")
    assert result.exit_code == 0, result.output
    line = _warning(result)
    assert "1 of 1 points" in line
    record = json.loads((tmp_path / "sw" / "sweep.json").read_text())["points"][0]
    assert record["warning"].startswith("warning:")
