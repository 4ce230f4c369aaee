"""Interrupted writes never lose a store: kill the writer at many points, then check.

A folder store is replaced in three steps (old set aside, new renamed in, old deleted);
whatever moment the writer dies, the old or the new store is whole and a later run removes
the leftovers. SIGTERM is handled like Ctrl-C: nothing is left behind at all.
"""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from viform._io import atomic_path, clean_stale
from viform._validate import ViformError
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes

WRITER = """
import sys
import numpy as np
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes
streams = [SpikeStream(np.random.default_rng(s).random((96, 8, 16)) < 0.3, 40000.0) for s in (0, 1)]
print("ready", flush=True)
i = 0
while True:
    save_spikes(sys.argv[1], streams[i % 2], block_ticks=4)
    i += 1
"""

CLI_WRITER = """
import sys
from viform.cli import _install_sigterm, main
_install_sigterm()  # what main() does first: a SIGTERM however soon after "ready" is the command's to handle
print("ready", flush=True)
while True:
    rc = main(["simulate", "translating", "--duration", "0.02", "--height", "8", "--width", "16",
               "--out", sys.argv[1], "--no-noise"])
    if rc:
        sys.exit(rc)
"""


def streams():
    return [np.random.default_rng(s).random((96, 8, 16)) < 0.3 for s in (0, 1)]


def _start(script, path):
    proc = subprocess.Popen([sys.executable, "-c", script, str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    return proc


def _leftovers(folder):
    return [p.name for p in folder.iterdir() if ".viform-" in p.name]


@pytest.mark.parametrize("name", ["s.zarr", "s.npz"])
def test_sigkill_at_many_points_leaves_old_or_new_store_whole(tmp_path, name):
    path = tmp_path / name
    a, b = streams()
    save_spikes(path, SpikeStream(a, 40_000.0), block_ticks=4)
    rng = np.random.default_rng(5)
    for _ in range(4):
        proc = _start(WRITER, path)
        time.sleep(rng.uniform(0.0, 0.3))
        proc.kill()
        proc.wait(600)
        source = open_spikes(path)  # restores an old store set aside by the dead writer
        source.verify()
        bits = source.read_ticks(0, 96)
        assert np.array_equal(bits, a) or np.array_equal(bits, b)
        clean_stale(path)  # what the next write does first
        assert _leftovers(tmp_path) == []


def test_killed_between_renames_restores_the_old_store(tmp_path):
    """The worst moment: old store set aside, new one not yet renamed in."""
    path = tmp_path / "s.zarr"
    a, b = streams()
    save_spikes(path, SpikeStream(a, 40_000.0))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    os.rename(path, tmp_path / f".s.zarr.viform-old-{dead}-x")
    save_spikes(tmp_path / f".s.zarr.viform-tmp-{dead}-y.zarr", SpikeStream(b, 40_000.0))
    assert np.array_equal(open_spikes(path).read_ticks(0, 96), a)
    clean_stale(path)
    assert _leftovers(tmp_path) == []


def test_sigterm_leaves_nothing_behind(tmp_path):
    path = tmp_path / "c.zarr"
    rng = np.random.default_rng(9)
    for _ in range(2):
        proc = _start(CLI_WRITER, path)
        time.sleep(rng.uniform(0.2, 0.6))
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=1800)  # a hang guard only
        assert proc.returncode == 143, err
        assert "Traceback" not in err
        assert _leftovers(tmp_path) == []  # no cleanup run needed
        if path.exists():
            open_spikes(path).verify()


def test_output_checked_before_work(tmp_path):
    (tmp_path / "d.dat").mkdir()
    with pytest.raises(ViformError, match="existing folder"):
        with atomic_path(tmp_path / "d.dat"):
            raise AssertionError("never reached")
    (tmp_path / "f.zarr").write_text("x")
    with pytest.raises(ViformError, match="existing file"):
        save_spikes(tmp_path / "f.zarr", SpikeStream(np.zeros((2, 2, 8), bool), 1e3))
    live = tmp_path / f".x.dat.viform-tmp-{os.getpid()}-abc.dat"
    live.write_text("mine")
    clean_stale(tmp_path / "x.dat")
    assert live.exists()  # a live writer's temporary is left alone


# A .dat and its sidecar are two files, renamed in one after the other: this writer is killed
# (SIGKILL, no cleanup) exactly at one of those renames.
KILL_AT_RENAME = """
import os, signal, sys
import numpy as np
from viform.stream.container import SpikeStream
from viform.stream.dat import write_dat
path, moment, with_sidecar = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
real = os.replace
def replace(src, dst):
    if os.fspath(dst) == {"data": path, "sidecar": path + ".json"}[moment]:
        os.kill(os.getpid(), signal.SIGKILL)
    return real(src, dst)
os.replace = replace
write_dat(path, SpikeStream(np.random.default_rng(1).random((96, 8, 16)) < 0.3, 40000.0), sidecar=with_sidecar)
"""


def _kill_at(path, moment, with_sidecar=True):
    proc = subprocess.run([sys.executable, "-c", KILL_AT_RENAME, str(path), moment, "1" if with_sidecar else "0"],
                          capture_output=True, text=True, timeout=1800)
    assert proc.returncode == -signal.SIGKILL, proc.stderr


@pytest.mark.parametrize("moment, survivor", [("data", 0), ("sidecar", 1)])
def test_dat_killed_at_either_rename_reads_a_whole_pair(tmp_path, moment, survivor):
    """Killed before the data rename: the old pair; between the renames: the new data, whose
    sidecar waits beside the old one and is picked because its checksum matches. The next
    write removes what the dead writer left."""
    path = tmp_path / "s.dat"
    a, b = streams()
    save_spikes(path, SpikeStream(a, 40_000.0))
    _kill_at(path, moment)
    source = open_spikes(path)
    assert source.verify()["verified"]
    assert np.array_equal(source.read_ticks(0, 96), (a, b)[survivor])
    assert open_spikes(path).sidecar["blake2b"] == source.sidecar["blake2b"]  # settled on disk, not per read
    save_spikes(path, SpikeStream(a, 40_000.0))
    assert _leftovers(tmp_path) == []
    assert np.array_equal(open_spikes(path).read_ticks(0, 96), a)


def test_dat_without_sidecar_never_leaves_a_wrong_one(tmp_path):
    """sidecar=False removes the old sidecar just before the data goes in: a kill there leaves
    the old data without a sidecar (read with its size given), never with another's."""
    path = tmp_path / "s.dat"
    a, _ = streams()
    save_spikes(path, SpikeStream(a, 40_000.0))
    _kill_at(path, "data", with_sidecar=False)
    assert not (tmp_path / "s.dat.json").exists()
    assert np.array_equal(open_spikes(path, 8, 16).read_ticks(0, 96), a)


def test_dat_sigkill_at_random_points_reads_old_or_new(tmp_path):
    path = tmp_path / "s.dat"
    a, b = streams()
    save_spikes(path, SpikeStream(a, 40_000.0), block_ticks=4)
    rng = np.random.default_rng(11)
    for _ in range(5):
        proc = _start(WRITER, path)
        time.sleep(rng.uniform(0.0, 0.3))
        proc.kill()
        proc.wait(600)
        source = open_spikes(path)
        assert source.verify()["verified"]
        bits = source.read_ticks(0, 96)
        assert np.array_equal(bits, a) or np.array_equal(bits, b)
    save_spikes(path, SpikeStream(b, 40_000.0))
    assert _leftovers(tmp_path) == []


def campaign(kills: int, seed: int) -> dict:
    """Kill a writer that rewrites a .dat in a loop ``kills`` times at random moments; count what
    a reader then finds: the old or new stream whole, a refused pair, or wrong bits."""
    import tempfile
    from pathlib import Path

    a, b = streams()
    rng = np.random.default_rng(seed)
    counts = {"whole": 0, "refused": 0, "wrong": 0}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "s.dat"
        save_spikes(path, SpikeStream(a, 40_000.0))
        for _ in range(kills):
            proc = _start(WRITER, path)
            time.sleep(rng.uniform(0.0, 0.3))
            proc.kill()
            proc.wait(600)
            try:
                source = open_spikes(path)
                source.verify()
                bits = source.read_ticks(0, 96)
            except ViformError:
                counts["refused"] += 1
                save_spikes(path, SpikeStream(a, 40_000.0))  # start again from a whole pair
                continue
            counts["whole" if np.array_equal(bits, a) or np.array_equal(bits, b) else "wrong"] += 1
    return counts


if __name__ == "__main__":  # python tests/stream/test_atomic.py --kills 30 --seed 1
    import argparse

    parser = argparse.ArgumentParser(description="SIGKILL campaign on .dat writes")
    parser.add_argument("--kills", type=int, default=30)
    parser.add_argument("--seed", type=int, default=1)
    opts = parser.parse_args()
    result = campaign(opts.kills, opts.seed)
    print(f"{opts.kills} kills: {result['whole']} whole pairs, {result['refused']} refused, "
          f"{result['wrong']} with wrong bits")


def test_interrupts_are_held_inside_a_deferred_section_and_raised_after():
    """SIGTERM inside interrupts_deferred() (zarr's calls) waits for the section's end, then ends the command."""
    from viform._io import interrupts_deferred
    from viform.cli import _install_sigterm, _Terminated

    previous = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a fresh process (other tests may change it)
    _install_sigterm()
    reached = []
    try:
        with pytest.raises(_Terminated):
            with interrupts_deferred():
                with interrupts_deferred():  # nested: held until the outermost section ends
                    os.kill(os.getpid(), signal.SIGTERM)
                    time.sleep(0.05)  # the handler runs here
                    reached.append("inner")
                reached.append("outer")
        assert reached == ["inner", "outer"]
        with pytest.raises(KeyboardInterrupt):  # outside a section: at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
    finally:
        signal.signal(signal.SIGTERM, previous[0])
        signal.signal(signal.SIGINT, previous[1])


# ---------------------------------------------------------------- the rename windows, stopped and killed
# The writer stops itself (SIGSTOP) right after one of its renames; while it is stopped a reader
# opens the output, then the writer is killed (SIGKILL: no cleanup) or let go on.
STOP_AFTER_RENAME = """
import os, signal, sys
import numpy as np
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes
path, window = sys.argv[1], sys.argv[2]
def stopping(real):
    def rename(src, dst):
        real(src, dst)
        if (window == "aside" and os.fspath(src) == path) or (window in ("in", "data") and os.fspath(dst) == path):
            os.kill(os.getpid(), signal.SIGSTOP)
    return rename
os.rename, os.replace = stopping(os.rename), stopping(os.replace)
save_spikes(path, SpikeStream(np.random.default_rng(1).random((96, 8, 16)) < 0.3, 40000.0), block_ticks=32)
"""


def _stopped_writer(path, window):
    proc = subprocess.Popen([sys.executable, "-c", STOP_AFTER_RENAME, str(path), window], stderr=subprocess.PIPE,
                            text=True)
    _, status = os.waitpid(proc.pid, os.WUNTRACED)  # returns once the writer has stopped itself
    assert os.WIFSTOPPED(status), (status, proc.stderr.read())
    return proc


def _read_whole(path):
    source = open_spikes(path)
    assert source.verify()["verified"]
    return source.read_ticks(0, 96)


@pytest.mark.parametrize("name, window", [("s.dat", "data"), ("s.zarr", "aside"), ("s.zarr", "in")])
@pytest.mark.parametrize("then", ["kill", "continue"])
def test_a_reader_in_a_rename_window_sees_the_old_or_the_new_output(tmp_path, name, window, then):
    """.dat: between the data's rename and its sidecar's (new data, old sidecar, new sidecar pending);
    zarr: between setting the old store aside and renaming the new one in (no store under the name),
    and between that and deleting the old one. The reader sees a whole old or new output, never new
    data with an old sidecar; after a kill, the next write leaves nothing behind."""
    path = tmp_path / name
    a, b = streams()
    save_spikes(path, SpikeStream(a, 40_000.0), block_ticks=32)
    proc = _stopped_writer(path, window)
    try:
        bits = _read_whole(path)
        assert np.array_equal(bits, a) or np.array_equal(bits, b)
        if window == "data":
            assert np.array_equal(bits, b)  # the pending sidecar matches the new data: the reader renames it in
    finally:
        if then == "kill":
            proc.kill()
        else:
            os.kill(proc.pid, signal.SIGCONT)
        proc.wait()
    bits = _read_whole(path)
    if then == "continue":
        assert proc.returncode == 0, proc.stderr.read()
        assert np.array_equal(bits, b) and _leftovers(tmp_path) == []
    else:
        assert np.array_equal(bits, a) or np.array_equal(bits, b)
        save_spikes(path, SpikeStream(a, 40_000.0))
        assert _leftovers(tmp_path) == [] and np.array_equal(_read_whole(path), a)


# SIGTERM at chosen moments of `viform simulate` (the process signals itself there): every
# moment ends with exit 143, one line, and no temporary file left (only SIGKILL may leave one).
TERM_AT = """
import os, signal, sys, tempfile
from viform import _io
from viform.cli import main
from viform.sensors.spike import SpikeSensor
moment = sys.argv[2]
def term():
    os.kill(os.getpid(), signal.SIGTERM)
if moment == "temporary":  # right after the temporary file is created
    real_mkstemp = tempfile.mkstemp
    def mkstemp(*args, **kwargs):
        made = real_mkstemp(*args, **kwargs)
        if _io.TMP_MARK in made[1]:
            term()
        return made
    tempfile.mkstemp = mkstemp
elif moment == "block":  # after the first block of spikes is simulated, before it is written
    real_blocks = SpikeSensor._packed_blocks
    def blocks(self, *args, **kwargs):
        for i, item in enumerate(real_blocks(self, *args, **kwargs)):
            if i == 0:
                term()
            yield item
    SpikeSensor._packed_blocks = blocks
elif moment == "fsync":  # the data is complete, not yet renamed in
    real_fsync = os.fsync
    def fsync(fd):
        real_fsync(fd)
        term()
    os.fsync = fsync
elif moment == "rename":  # during the data's rename
    real_replace = os.replace
    def replace(src, dst):
        if os.fspath(dst) == sys.argv[1]:
            term()
        real_replace(src, dst)
    os.replace = replace
sys.exit(main(["simulate", "translating", "--duration", "0.02", "--height", "64", "--width", "128",
               "--out", sys.argv[1], "--json"]))
"""


@pytest.mark.parametrize("moment", ["temporary", "block", "fsync", "rename"])
def test_sigterm_during_simulate_cleans_up_at_once(tmp_path, moment):
    path = tmp_path / "s.dat"
    proc = subprocess.run([sys.executable, "-c", TERM_AT, str(path), moment], capture_output=True, text=True)
    assert proc.returncode == 143, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip() and "%|" not in line
             and not line.startswith("compiling ")]
    assert len(lines) == 1 and lines[0].startswith("viform: interrupted"), proc.stderr
    assert _leftovers(tmp_path) == []  # at once: no later run needed to clean up
    if moment == "rename":  # held until the data and its sidecar are in: a whole pair, and said so
        assert "kept 1 complete file" in lines[0] and str(path) in lines[0]
        assert open_spikes(path).verify()["verified"]
    else:
        assert not path.exists() and "no output was left" in lines[0]


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


CHAIN = textwrap.dedent('''
    import sys
    import viform
    from viform._numba_cache import share_compiles
    from viform.cli import _install_sigterm
    if sys.argv[1] == "lock first":
        share_compiles()
    _install_sigterm()
    import numba.core.dispatcher as d
    share_compiles()
    f, chain = d.Dispatcher.compile, []
    while f is not None:
        chain.append(f.__code__.co_filename.replace("\\\\", "/").split("/")[-1])
        f = getattr(f, "__wrapped__", None)
    print(" ".join(chain))
''')


def test_the_compile_file_lock_stays_outside_the_deferral():
    # waiting for another process's compile (VIFORM_SHARE_COMPILES) stays interruptible: the file lock wraps
    # the deferred compile, whichever was installed first
    env = {k: v for k, v in os.environ.items() if k != "VIFORM_SHARE_COMPILES"}
    for order in ("lock first", "deferral first"):
        out = subprocess.run([sys.executable, "-c", CHAIN, order], capture_output=True, text=True, check=True,
                             env=env).stdout.split()
        assert out == ["_numba_cache.py", "_io.py", "dispatcher.py"], (order, out)
