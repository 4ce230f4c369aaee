"""Shared fixtures: the real spike data kept beside the project (never copied into it); the whole
suite on two worker processes."""

import os
from pathlib import Path

import pytest

#: Worker processes for a plain ``pytest`` (the README's command: no paths, no ``-n``) when
#: pytest-xdist (a test extra) is installed; ``VIFORM_TEST_WORKERS=N`` sets another number
#: (0: one process), and ``-n N`` or ``-p no:xdist`` on the command line decide as usual.
TEST_WORKERS = 2


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """Run the whole suite on :data:`TEST_WORKERS` processes (at most one per CPU), test files
    spread over them by work stealing; runs of chosen paths stay in one process."""
    if (not config.pluginmanager.hasplugin("xdist") or hasattr(config, "workerinput")
            or config.option.numprocesses is not None or config.option.dist != "no"
            or config.args_source != pytest.Config.ArgsSource.TESTPATHS
            or config.getoption("usepdb") or config.getoption("collectonly")):
        return
    workers = int(os.environ.get("VIFORM_TEST_WORKERS", TEST_WORKERS))
    workers = min(workers, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count())
    if workers >= 2:
        config.option.numprocesses = workers
        config.option.dist = "worksteal"

def pytest_configure(config):
    """Every test process compiles each viform kernel under its file lock, so the workers of one run
    compile a kernel once between them and load it from numba's cache (viform._numba_cache)."""
    from viform._numba_cache import share_compiles

    share_compiles()
    os.environ["VIFORM_SHARE_COMPILES"] = "1"  # and so do the commands the tests start in subprocesses
    from viform.cli import wait_passively

    wait_passively()  # numba's OpenMP threads sleep between kernels, as the command line's (README)


#: The real recordings (README, "Tests that read real recordings"): ``$VIFORM_SPIKE_DATA`` if set,
#: else ``<repo>/../shared/data/spike``.
SHARED_SPIKE_DATA = Path(os.environ.get("VIFORM_SPIKE_DATA")
                         or Path(__file__).resolve().parents[1].parent / "shared" / "data" / "spike")


@pytest.fixture(scope="session")
def spike_data_dir() -> Path:
    """The real recordings' folder; tests that need it are skipped when it is absent."""
    if not SHARED_SPIKE_DATA.is_dir():
        pytest.skip(f"shared spike data absent: {SHARED_SPIKE_DATA}")
    return SHARED_SPIKE_DATA
