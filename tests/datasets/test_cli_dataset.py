"""`viform dataset`: table / JSON output, exit status 1 on a failed clip, options checked before any work."""

from __future__ import annotations

import json
import shutil

import pytest

from viform.cli import main

H, W = 24, 32


def _args(src, out, *extra):
    return ["dataset", str(src), "--out", str(out), "--height", str(H), "--width", str(W),
            "--frame-rate-hz", "1000", "--gt-every", "2", "--seed", "7", "--block-ticks", "64", "--no-progress",
            *extra]


def test_cli_on_a_running_scheduler_resumes_the_reference(reference, source_clips, client2, tmp_path, capsys,
                                                          dataset_files):
    out = tmp_path / "ds"
    shutil.copytree(reference, out)
    address = client2.scheduler.address
    rc = main(_args(source_clips, out, "--scheduler", address, "--json", "--json-file", str(tmp_path / "s.json")))
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["skipped"] == 4 and summary["converted"] == 0 and summary["workers"] >= 1
    assert json.loads((tmp_path / "s.json").read_text())["skipped"] == 4
    assert dataset_files(out) == dataset_files(reference)


def test_cli_table_and_exit_status_1_when_a_clip_fails(source_with_broken_clip, client1, tmp_path, capsys):
    src = source_with_broken_clip
    rc = main(_args(src, tmp_path / "ds", "--scheduler", client1.scheduler.address))
    captured = capsys.readouterr()
    assert rc == 1
    assert "clips" in captured.out and "failed 1" in captured.out and "pixel-ticks/s" in captured.out
    assert "clip 'broken' failed" in captured.err
    assert (tmp_path / "ds" / "spike" / "clip0.dat").is_file()


@pytest.mark.parametrize("extra, flag", [
    (["--gt-every", "0"], "--gt-every"),
    (["--workers", "0"], "--workers"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
    (["--preset", "no-such-chip"], "no-such-chip"),
    (["--width", "33", "--height", "3"], "--height"),
    (["--max-lux", "-1"], "--max-lux"),
    (["--worker-memory", "lots"], "--worker-memory"),
])
def test_bad_options_exit_2_naming_the_option_before_any_work(source_clips, tmp_path, capsys, extra, flag):
    out = tmp_path / "ds"
    rc = main(_args(source_clips, out, *extra))
    err = capsys.readouterr().err
    assert rc == 2 and flag in err and err.count("\n") == 1, err
    assert not out.exists()


def test_frame_folders_need_a_frame_rate(source_clips, tmp_path, capsys):
    args = [a for a in _args(source_clips, tmp_path / "ds") if a not in ("--frame-rate-hz", "1000")]
    assert main(args) == 2
    assert "--frame-rate-hz" in capsys.readouterr().err


def test_unwritable_json_file_refused_before_work(source_clips, tmp_path, capsys):
    """--json-file under a regular file cannot be written: refused before any clip is made
    (a missing folder would be created, as for --out)."""
    out = tmp_path / "ds"
    (tmp_path / "no").write_text("a file")
    rc = main(_args(source_clips, out, "--json-file", str(tmp_path / "no" / "s.json")))
    err = capsys.readouterr().err
    assert rc == 2 and "--json-file" in err and err.count("\n") == 1, err
    assert not out.exists()


@pytest.mark.parametrize("extra, flag", [
    (["--scenes", "nonesuch", "--clips", "1", "--duration", "0.01"], "--scenes"),
    (["--scenes", "translating", "--clips", "0", "--duration", "0.01"], "--clips"),
    (["--scenes", "translating", "--duration", "0.01"], "--clips"),
    (["--scenes", "translating", "--clips", "1", "--duration", "0.01", "--truth-every-ticks", "0"],
     "--truth-every-ticks"),
    (["--scenes", "translating,translating", "--clips", "1", "--duration", "0.01"], "--scenes"),
    (["--scenes", "translating", "--clips", "1", "--duration", "1e-5"], "--duration"),
    (["SRC", "--scenes", "translating", "--clips", "1", "--duration", "0.01"], "--scenes"),
    (["SRC", "--pairs"], "--pairs"),
])
def test_scene_options_refused_in_one_line_before_any_work(extra, flag, source_clips, tmp_path, capsys):
    extra = [str(source_clips) if a == "SRC" else a for a in extra]
    out = tmp_path / "ds"
    rc = main(["dataset", *extra, "--out", str(out), "--height", "16", "--width", "24", "--no-progress",
               "--workers", "1"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and flag in err, err
    assert not out.exists()
