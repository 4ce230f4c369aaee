"""What a command that runs no compiled kernel loads: help, listings and refused input start without numba.

numba costs about 0.25 CPU-s to import (more once its compiler starts), so ``viform --help``, the
catalogues and a flag refused with exit status 2 must not pay it; nor may any command start dask,
matplotlib, OpenCV or TrackEval before it needs them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

HEAVY = ["numba", "llvmlite", "dask", "distributed", "zarr", "matplotlib", "cv2", "trackeval", "scipy.special",
         "scipy.linalg", "torch"]

NO_KERNEL = [
    (["--help"], 0),
    (["simulate", "--help"], 0),
    (["capture", "--help"], 0),
    (["sweep", "--help"], 0),
    (["sensors"], 0),
    (["scenes"], 0),
    (["simulate", "step", "--duration", "-1", "--out", "{tmp}/s.dat"], 2),
    (["simulate", "no-such-scene", "--duration", "0.01", "--out", "{tmp}/s.dat"], 2),
    (["capture", "step", "cmos", "--duration", "-1", "--out", "{tmp}/c"], 2),
    (["simulate", "step", "--duration", "0.01", "--device", "tpu", "--out", "{tmp}/s.dat"], 2),
]


def _loaded(argv: list[str]) -> tuple[int, list[str]]:
    """(exit status, heavy modules loaded) of ``viform ARGV`` in a fresh interpreter."""
    code = (
        "import json, sys\n"
        "from viform.cli import main\n"
        "try:\n"
        f"    status = main({argv!r})\n"
        "except SystemExit as exc:\n"
        "    status = exc.code\n"
        f"print(json.dumps([status, [m for m in {HEAVY!r} if m in sys.modules]]), file=sys.stderr)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "VIFORM_SHARE_COMPILES"}  # a user's plain start
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    status, loaded = json.loads(result.stderr.strip().splitlines()[-1])
    return status, loaded


@pytest.mark.parametrize(("argv", "status"), NO_KERNEL, ids=[" ".join(a[:2]) + f" ({s})" for a, s in NO_KERNEL])
def test_commands_that_run_no_kernel_load_no_heavy_library(argv, status, tmp_path):
    argv = [a.format(tmp=tmp_path) for a in argv]
    got, loaded = _loaded(argv)
    assert got == status, f"viform {' '.join(argv)} exited {got}"
    assert loaded == [], f"viform {' '.join(argv)} imported {loaded}"
    assert not list(tmp_path.iterdir()), "a refused command wrote a file"


def test_a_simulation_does_load_numba(tmp_path):
    """The check above can see numba: a run that simulates loads it."""
    got, loaded = _loaded(["simulate", "step", "--duration", "0.0001", "--out", str(tmp_path / "s.dat")])
    assert got == 0 and "numba" in loaded
