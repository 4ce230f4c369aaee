"""``viform flow`` and ``viform simulate --truth`` (issue 21 items 2–3): outputs, scores, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from viform.cli import _load_commands, main
from viform.cli.app import cli

_load_commands()


def _main(args, capsys):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out + err


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    folder = tmp_path_factory.mktemp("flowcli")
    out = folder / "tr.dat"
    result = _run("simulate", "translating", "--height", 32, "--width", 48, "--duration", 0.006, "--out", out,
                  "-q", 100, "--seed", 2, "--truth", folder / "truth", "--truth-every-ticks", 40)
    assert result.exit_code == 0, result.output
    return out


def test_simulate_writes_truth_beside_the_spikes(moving):
    folder = moving.parent / "truth"
    meta = json.loads((folder / "truth.json").read_text())
    assert meta["step_ticks"] == 40 and len(meta["frames"]) == 6 and meta["kinds"] == ["motion", "objects"]
    from viform.vision.flow import read_flo

    flow, valid = read_flo(folder / "flow" / meta["frames"][0]["flow"])
    np.testing.assert_allclose(flow[0][valid], 2.0, rtol=1e-6)  # 2000 px/s over 1 ms
    assert (folder / "mot" / "tr" / "gt" / "gt.txt").read_text() == ""  # translating: no labelled objects


def test_flow_scores_a_file_with_truth(moving, tmp_path):
    result = _run("flow", moving, "--at", 0.002, "--dt", 0.001, "--out", tmp_path / "f", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["truth"] and summary["scores"]["all"]["pixels"] > 500
    moving_px = summary["scores"]["moving"]
    assert moving_px["pixels"] > 500 and moving_px["relative_error"] < 0.5  # 2 px of motion, found
    assert summary["scores"]["zero_flow"]["moving"]["relative_error"] == pytest.approx(1.0)
    assert {p.name for p in (tmp_path / "f").iterdir()} == {"flow.npy", "confidence.npy", "flow.flo", "flow.png",
                                                           "metrics.json"}
    assert np.load(tmp_path / "f" / "flow.npy").shape == (2, 32, 48)


def test_a_field_with_no_still_pixels_says_so(moving, tmp_path):
    # the whole texture translates: the still-background line says there is none rather than vanishing
    result = _run("flow", moving, "--at", 0.002, "--dt", 0.001, "--out", tmp_path / "f")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert any(line.startswith("moving pixels (") for line in lines)
    assert "still background: none (every pixel with valid truth moves, as under a moving camera)" in lines


@pytest.fixture(scope="module")
def dilemma(tmp_path_factory):
    folder = tmp_path_factory.mktemp("flowdilemma")
    out = folder / "d.dat"
    result = _run("simulate", "dilemma", "--height", 64, "--width", 128, "--duration", 0.013, "--out", out,
                  "-q", 100, "--seed", 0)
    assert result.exit_code == 0, result.output
    return out


def test_headline_scores_the_moving_pixels_so_a_missed_motion_reads_missed(dilemma, tmp_path):
    # the dense flow alone barely moves the vehicle (+2.5 px): the headline must say so, whatever the still
    # background (most of the image) scores
    result = _run("flow", dilemma, "--at", 0.01, "--dt", 0.001, "--refine", "none", "--out", tmp_path / "f")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    headline = next(line for line in lines if line.startswith("moving pixels"))
    assert "missed" in headline and "zero flow" in headline
    vehicle = next(line for line in lines if " vehicle " in line)
    assert vehicle.split()[-3] == "missed"
    assert any(line.startswith("still background") for line in lines)
    # every printed score checked against an independent computation from the written flow and the truth
    from viform.light.catalog import builtin_scene

    summary = json.loads((tmp_path / "f" / "metrics.json").read_text())
    flow = np.load(tmp_path / "f" / "flow.npy").astype(float)
    scene = builtin_scene("dilemma", 64, 128)
    truth = scene.optical_flow_px(summary["t0_s"], summary["t1_s"])
    err = np.sqrt(((flow - truth.flow_px) ** 2).sum(axis=0))
    length = np.sqrt((truth.flow_px ** 2).sum(axis=0))
    moving_px = truth.valid & (length > 0.5)
    assert summary["scores"]["moving"]["epe_px"] == pytest.approx(err[moving_px].mean(), rel=1e-6)
    assert summary["scores"]["moving"]["relative_error"] == pytest.approx(err[moving_px].mean()
                                                                         / length[moving_px].mean(), rel=1e-6)
    assert summary["scores"]["moving"]["relative_error"] > 0.5
    still = truth.valid & (length == 0)
    assert summary["scores"]["still"]["median_false_motion_px"] == pytest.approx(
        np.median(np.sqrt((flow[:, still] ** 2).sum(axis=0))), abs=1e-6)
    vehicle_px = truth.valid & (scene.object_labels(summary["t0_s"]) == 1)
    assert summary["scores"]["objects"]["1 vehicle"]["epe_px"] == pytest.approx(err[vehicle_px].mean(), rel=1e-6)
    assert summary["scores"]["zero_flow"]["moving"]["epe_px"] == pytest.approx(length[moving_px].mean(), rel=1e-6)
    # the layered estimate finds the vehicle
    result = _run("flow", dilemma, "--at", 0.01, "--dt", 0.001, "--out", tmp_path / "g", "--json")
    found = json.loads(result.stdout)["scores"]
    assert found["objects"]["1 vehicle"]["relative_error"] < 0.5 < summary["scores"]["objects"]["1 vehicle"][
        "relative_error"]


@pytest.mark.parametrize("args, flag", [(("--dt", 0), "--dt"), (("--dt", -1e-3), "--dt"), (("--dt", 1.0), "--dt"),
                                        (("--at", 0.5), "--at")])
def test_bad_intervals_exit_2_and_write_nothing(moving, tmp_path, args, flag, capsys):
    options = {"--at": 0.002, "--dt": 0.001, **dict(zip(args[::2], args[1::2], strict=True))}
    code, text = _main(["flow", moving, "--out", tmp_path / "f", *[x for kv in options.items() for x in kv]], capsys)
    assert code == 2 and text.count("\n") == 1
    assert flag in text and "Traceback" not in text
    assert not (tmp_path / "f").exists()


def test_score_without_truth_is_refused(tmp_path, capsys):
    np.savez(tmp_path / "foreign.npz", spk=np.random.default_rng(0).random((200, 16, 24)) < 0.2)
    code, text = _main(["flow", tmp_path / "foreign.npz", "--at", "0.001", "--dt", "0.001", "--score",
                        "--out", tmp_path / "f"], capsys)
    assert code == 2 and "--score" in text and "no truth" in text
    assert not (tmp_path / "f").exists()
    # without --score the flow is still estimated
    code, text = _main(["flow", tmp_path / "foreign.npz", "--at", "0.001", "--dt", "0.001",
                        "--out", tmp_path / "g"], capsys)
    assert code == 0 and "truth: none" in text


def test_truth_of_a_file_scene_is_refused(tmp_path, capsys):
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "still.png", np.full((16, 24), 128, np.uint8))
    code, text = _main(["simulate", tmp_path / "still.png", "--duration", "0.001", "--out", tmp_path / "s.dat",
                        "--truth", tmp_path / "t"], capsys)
    assert code == 2 and "--truth" in text and "no truth" in text
    assert not (tmp_path / "s.dat").exists() and not (tmp_path / "t").exists()
