"""--json-file: every command has it, with one rule (viform._io.check_json_file) and one help text.

The rule is --out's: missing folders are created when the file is written; an existing folder,
a path under a regular file or an unwritable folder is refused before any work (exit 2, one
line naming --json-file). The file holds exactly what --json prints.
"""

import json
import os

import numpy as np
import pytest

from viform._io import JSON_FILE_HELP
from viform.cli import _load_commands, main
from viform.cli._types import flag_of, walk
from viform.cli.app import cli
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes

#: Smallest valid invocation of each command ({clip}: a small .dat with its sidecar; {tmp}: a folder).
ARGS = {
    "simulate": ["translating", "--duration", "0.0005", "--height", "4", "--width", "8", "--out", "{tmp}/s.dat"],
    "reconstruct": ["{clip}", "--method", "accumulation", "--at", "0.0002", "--out", "{tmp}/r.png"],
    "info": ["{clip}"],
    "verify": ["{clip}"],
    "demo": ["--out", "{tmp}/demo"],
    "characterize": ["cmos", "--size", "8", "--out", "{tmp}/figs"],
    "highspeed": ["translating", "--out", "{tmp}/hs"],
    "highspeed-figures": [],
    "gated": ["--out", "{tmp}/gated"],
    "encode": ["{clip}", "{tmp}/e.vfc"],
    "decode": ["{tmp}/e.vfc", "{tmp}/d.dat"],
    "dr": [],
    "lightcomm": [],
    "display": [],
    "dataset": ["{tmp}", "--out", "{tmp}/ds"],
    "capture": ["cmos", "translating", "--duration", "0.001", "--out", "{tmp}/c.npz"],
    "compare": ["translating", "--out", "{tmp}/cmp"],
    "sweep": ["dilemma", "--sensor", "cmos", "--workers", "0", "--out", "{tmp}/sw"],
    "chip-figures": ["--out", "{tmp}/chip"],
    "calibrate": ["{clip}"],
    "flow": ["{clip}", "--at", "0.0002", "--dt", "0.0002", "--out", "{tmp}/flow"],
    "track": ["{clip}", "--every", "10", "--out", "{tmp}/trk"],
    "sensors": [],
}


def run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    path = tmp_path_factory.mktemp("clip") / "clip.dat"
    save_spikes(path, SpikeStream(np.random.default_rng(0).random((40, 8, 16)) < 0.2, 40_000.0))
    return path


def _args(name, clip, tmp):
    return [name, *(a.format(clip=clip, tmp=tmp) for a in ARGS[name])]


def test_every_command_has_json_file_with_the_same_help():
    _load_commands()
    commands = {c.name: c for c in walk(cli)}
    assert set(ARGS) <= set(commands)  # a new command is checked here; give it a row in ARGS too
    for name, command in commands.items():
        options = {flag_of(p): p for p in command.params}
        assert "--json" in options and "--json-file" in options, name
        assert options["--json-file"].help == JSON_FILE_HELP, name


@pytest.mark.parametrize("name", sorted(ARGS))
def test_bad_json_file_refused_before_any_work(name, clip, tmp_path, capsys):
    """An existing folder, or a path under a regular file: one line naming --json-file, nothing written."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "a-folder.json").mkdir()
    (work / "a-file").write_text("x")
    before = sorted(p.name for p in work.iterdir())
    for bad, why in ((work / "a-folder.json", "is an existing folder"),
                     (work / "a-file" / "x.json", "is not a folder")):
        code, _, err = run(_args(name, clip, work) + ["--json-file", str(bad)], capsys)
        assert code == 2, err
        assert err.count("\n") == 1 and "--json-file" in err and why in err, err
        assert sorted(p.name for p in work.iterdir()) == before  # no output, no temporary file


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_unwritable_folder_refused(clip, tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        code, _, err = run(["info", str(clip), "--json-file", str(locked / "new" / "i.json")], capsys)
    finally:
        locked.chmod(0o700)
    assert code == 2 and err.count("\n") == 1 and "--json-file" in err and "not writable" in err


@pytest.mark.parametrize("name", ["info", "verify", "dr", "simulate", "reconstruct"])
def test_missing_folders_are_created_and_hold_what_json_prints(name, clip, tmp_path, capsys):
    target = tmp_path / "new" / "deeper" / "r.json"
    code, out, err = run(_args(name, clip, tmp_path) + ["--json", "--json-file", str(target)], capsys)
    assert code == 0, err
    assert json.loads(target.read_text()) == json.loads(out)
    code, out, err = run(_args(name, clip, tmp_path) + ["--json-file", str(target)], capsys)  # replaced
    assert code == 0, err
    assert json.loads(target.read_text())
