"""Processes that start together compile a kernel once (viform._numba_cache.share_compiles)."""

import json
import os
import subprocess
import sys
import textwrap

PROBE = textwrap.dedent('''
    import numba
    import numpy as np

    @numba.njit(cache=True)
    def kernel(x):
        total = 0.0
        for i in range(x.size):
            v = x[i]
            for k in range(1, 8):
                total += np.sin(v * k) * np.cos(v / k) + np.exp(-v * k) + np.log1p(v + k)
        return total
''')

RUN = textwrap.dedent('''
    import json, os, sys, time
    import viform._numba_cache as shared
    shared.PACKAGES = ("probe_kernels",)
    assert shared.share_compiles()
    sys.path.insert(0, sys.argv[1])
    import numpy as np
    import probe_kernels
    go = os.path.join(sys.argv[1], "go")
    while not os.path.exists(go):
        time.sleep(0.01)
    value = probe_kernels.kernel(np.arange(5.0))
    stats = probe_kernels.kernel.stats
    print(json.dumps({"value": value, "hits": sum(stats.cache_hits.values()),
                      "misses": sum(stats.cache_misses.values())}))
''')


def test_two_processes_compile_a_kernel_once(tmp_path):
    (tmp_path / "probe_kernels.py").write_text(PROBE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    procs = [subprocess.Popen([sys.executable, "-c", RUN, str(tmp_path)], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    (tmp_path / "go").write_text("")
    results = []
    for p in procs:
        out, err = p.communicate(timeout=1800)
        assert p.returncode == 0, err
        results.append(json.loads(out.strip().splitlines()[-1]))
    assert len({r["value"] for r in results}) == 1
    # one process compiled (a miss); the others waited for its lock and loaded its kernel (hits)
    assert sum(r["misses"] for r in results) == 1, results
    assert sum(r["hits"] for r in results) == 1, results
    assert list((tmp_path / "cache").rglob("*.compile-lock"))


def test_other_kernels_compile_as_numba_does(tmp_path):
    """A kernel outside viform's packages takes no lock (and one without a disk cache neither)."""
    import numba

    import viform._numba_cache as shared

    assert shared.share_compiles()

    @numba.njit(cache=False)
    def plain(x):
        return x + 1

    assert plain(1) == 2
    assert shared._lock_path(plain) is None

