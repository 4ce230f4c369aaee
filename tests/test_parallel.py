"""viform's own local dask clusters (:func:`viform._parallel.open_client`): workers forked from a fork server
that has imported what a command's tasks need."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import viform
from viform.datasets import build
from viform.measure.sweep import run


@pytest.mark.parametrize("modules", [run.WORKER_MODULES, build.WORKER_MODULES], ids=["sweep", "dataset"])
def test_workers_are_forked_with_the_commands_modules_imported(modules):
    """A local cluster's worker finds the command's modules, numba's registries and viform's preload imported
    by the fork server (:data:`viform._parallel.WORKER_START`), and has the one-thread settings of the
    workers' environment; the process's own dask settings are left as they were (a fresh process, where
    distributed is not imported yet, as on the command line)."""
    code = ("import dask, json, sys\nfrom viform._parallel import open_client\n"
            "modules = tuple(sys.argv[1:])\n"
            "def seen():\n"
            "    import os, sys\n"
            "    from numba.core.registry import cpu_target\n"
            "    return [all(m in sys.modules for m in modules), 'viform._worker_preload' in sys.modules,\n"
            "            len(cpu_target.target_context._registries) > 0, os.environ.get('OMP_NUM_THREADS')]\n"
            "client, cluster = open_client(1, None, 'auto', preload=modules)\n"
            "try:\n"
            "    print(json.dumps([list(client.run(seen).values()),\n"
            "                      dask.config.get('distributed.scheduler.work-stealing')]))\n"
            "finally:\n"
            "    client.close()\n"
            "    cluster.close()\n")
    done = subprocess.run([sys.executable, "-c", code, *modules], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(Path(viform.__file__).parents[1])})
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == [[[True, True, True, "1"]], True]
