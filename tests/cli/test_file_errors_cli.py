"""Reader errors name only flags the command has (issue 33.3): the library names its parameters
(``allow_partial=True``, ``height=250``), each command keeps the remedies it can offer, as flags."""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from viform.cli import main
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes
from viform.stream.sidecar import sidecar_path


def run(args):
    err, out = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def cut_dat(tmp_path_factory):
    """A .dat without sidecar whose last frame is cut short."""
    folder = tmp_path_factory.mktemp("cut")
    path = save_spikes(folder / "p.dat", SpikeStream(np.random.default_rng(0).random((200, 8, 16)) < 0.2,
                                                      40_000.0, 60.0))
    sidecar_path(path).unlink()
    path.write_bytes(path.read_bytes()[:-5])
    return path


COMMANDS = {  # the commands that read a spike file; info and verify have --allow-partial
    "reconstruct": ["--at", "0.001", "--out", "{out}/r.png"],
    "track": ["--out", "{out}/t"],
    "flow": ["--at", "0.002", "--out", "{out}/f"],
    "calibrate": ["--out", "{out}/c.json"],
    "encode": ["{out}/e.vfc"],
    "info": [],
    "verify": [],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_cut_dat_names_only_the_flags_of_the_command(cut_dat, tmp_path, command):
    args = [command, cut_dat, *[a.format(out=tmp_path) for a in COMMANDS[command]], "--height", "8", "--width", "16"]
    rc, _, err = run(args)
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 2 and len(lines) == 1 and "not a whole number of 16×8 frames" in lines[0], err
    assert "check --height 8 and --width 16" in lines[0]
    has_partial = command in ("info", "verify")
    assert ("--allow-partial" in lines[0]) == has_partial, lines[0]
    assert "allow_partial" not in lines[0]


def test_the_library_names_its_parameters(cut_dat):
    from viform._validate import ViformError
    from viform.stream.io import open_spikes

    with pytest.raises(ViformError, match="check height=8 and width=16; keep the whole frames with "
                                          "allow_partial=True") as caught:
        open_spikes(cut_dat, 8, 16)
    assert "--" not in str(caught.value)
    assert open_spikes(cut_dat, 8, 16, allow_partial=True).n_ticks == 199
