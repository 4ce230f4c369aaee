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


#: A command's handlers (viform.cli), then a SIGTERM that arrives while numba compiles a kernel: sent by the
#: kernel's own typing (an intrinsic), so the handler runs in the middle of the compile.
SIGNAL_IN_COMPILE = textwrap.dedent('''
    import os, signal, sys
    if sys.argv[1] == "before":
        import numba  # numba already imported when the handlers are installed
    from viform.cli import _install_sigterm, _Terminated
    _install_sigterm()
    assert ("numba.core.dispatcher" in sys.modules) == (sys.argv[1] == "before")
    import numba
    from numba.extending import intrinsic

    @intrinsic
    def signalled(typingctx, x):
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(10_000))  # the handler runs here, while the caller is being compiled

        def codegen(context, builder, signature, args):
            return args[0]
        return x(x), codegen

    @numba.njit
    def kernel(x):
        return signalled(x) + 1.0

    try:
        kernel(1.0)
        print("not interrupted")
    except _Terminated:
        print("interrupted; compiled:", [str(s) for s in kernel.signatures], "then", kernel(2.0))
''')


def test_an_interrupt_during_a_compile_is_raised_when_the_compile_returns():
    # the command's SIGTERM, arriving mid-compile, neither cuts numba's compile (a half-made library, or an
    # exception dropped inside a ctypes callback from LLVM: the command runs on) nor is lost: it is raised
    # once the kernel is compiled, whether numba was imported before the handlers or after (the import hook)
    env = {k: v for k, v in os.environ.items() if k != "VIFORM_SHARE_COMPILES"}  # (which imports numba)
    for numba_imported in ("before", "after"):
        run = subprocess.run([sys.executable, "-c", SIGNAL_IN_COMPILE, numba_imported], capture_output=True,
                             text=True, timeout=600, env=env)
        assert run.returncode == 0, run.stderr
        assert run.stdout.strip() == "interrupted; compiled: ['(float64,)'] then 3.0", (numba_imported, run.stdout)
