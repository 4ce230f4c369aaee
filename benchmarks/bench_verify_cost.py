"""The cost of checking what is read (issue 26): ``reconstruct --at`` on 100 MB files, with and without checks.

For each file — viform's ``.dat`` + sidecar (per-block CRC-32s), viform's ``.npz`` (per-block
CRC-32s), another tool's ``.npz`` (no block checksums: one streamed pass over the member for
its zip CRC-32 before the first image), viform's zarr (per-chunk CRC-32s) — the command
``viform reconstruct FILE --method M --at T --out x.png`` is run in this process (median of
``--repeat`` runs, after one warm-up) as it is, then with the checks replaced by plain reads
(the reference), interleaved. Printed: both times, the difference as a share of the checked
time, the time spent inside the checks as a share of the same run (robust to load that
changes between runs), and peak memory (tracemalloc, Python-visible) of one checked run.
Goal: checks ≤ 20 % of the time.

Run:  python benchmarks/bench_verify_cost.py [--mb 100] [--repeat 5] [--at 0.1]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import tracemalloc
import zlib
from contextlib import contextmanager, redirect_stdout
from io import StringIO
from pathlib import Path

import numpy as np

from viform.cli import main
from viform.stream import checksums, npz, zarr_store
from viform.stream.container import SpikeSource
from viform.stream.io import save_spikes

H, W, CLOCK_HZ = 250, 400, 40_000.0


class RandomStream(SpikeSource):
    """Bernoulli spikes generated block by block (the file is written without holding it)."""

    def __init__(self, n_ticks: int, p: float = 0.05):
        self.height, self.width, self.n_ticks, self.clock_hz = H, W, n_ticks, CLOCK_HZ
        self.threshold_electrons, self.start_time_s, self.metadata = 100.0, 0.0, {}
        self.p = p

    def read_ticks(self, start, stop):
        rng = np.random.default_rng(start)
        return rng.random((max(0, stop - start), H, W), dtype=np.float32) < self.p


@contextmanager
def unchecked():
    """The reference: the same reads with every check replaced by a plain read."""
    block_read = checksums.BlockReader.read
    check_member = npz.NpzSpikes._check_member

    def plain(self, offset, count):
        return self._read_raw(offset, count)

    def first_read(self, keep=(0, 0)):
        self._zip_checked = True  # as if checked: reads go straight to the member
        return self._member_read(*keep)

    def zarr_plain(self, start, stop):
        return self._load(start, stop)

    zarr_read = zarr_store.ZarrSpikeStore._read_packed
    checksums.BlockReader.read = plain
    npz.NpzSpikes._check_member = first_read
    zarr_store.ZarrSpikeStore._read_packed = zarr_plain
    try:
        yield
    finally:
        checksums.BlockReader.read = block_read
        npz.NpzSpikes._check_member = check_member
        zarr_store.ZarrSpikeStore._read_packed = zarr_read


class TimedChecks:
    """Seconds spent inside the checks themselves (CRC-32 of blocks, the streamed zip-CRC pass)."""

    def __init__(self):
        self.seconds = 0.0

    @contextmanager
    def active(self):
        real_zlib, check_member = checksums.zlib, npz.NpzSpikes._check_member
        timer = self

        class Zlib:
            @staticmethod
            def crc32(data, value=0):
                started = time.perf_counter()
                try:
                    return zlib.crc32(data, value)
                finally:
                    timer.seconds += time.perf_counter() - started

        def timed_check(source, keep=(0, 0)):
            started = time.perf_counter()
            try:
                return check_member(source, keep)
            finally:
                timer.seconds += time.perf_counter() - started

        checksums.zlib, zarr_store.zlib, npz.NpzSpikes._check_member = Zlib, Zlib, timed_check
        try:
            yield self
        finally:
            checksums.zlib, zarr_store.zlib, npz.NpzSpikes._check_member = real_zlib, real_zlib, check_member


def run(args) -> float:
    started = time.perf_counter()
    with redirect_stdout(StringIO()):
        rc = main(args)
    assert rc == 0, args
    return time.perf_counter() - started


def main_bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mb", type=float, default=100.0, help="size of each file, MB")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--at", type=float, default=0.1, help="instant read, s (files last 0.2 s at 100 MB)")
    parser.add_argument("--method", default="interval")
    a = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="viform-bench-verify-") as folder:
        folder = Path(folder)
        files = {}
        dat_ticks = int(a.mb * 1e6 / (H * W / 8))  # packed bits: 12.5 kB a tick
        files["dat (viform)"] = save_spikes(folder / "s.dat", RandomStream(dat_ticks))
        npz_ticks = int(a.mb * 1e6 / (H * W))  # one byte a pixel in the member
        files["npz (viform)"] = save_spikes(folder / "s.npz", RandomStream(npz_ticks))
        foreign = folder / "zoo.npz"
        np.savez(foreign, spk=RandomStream(npz_ticks).read_ticks(0, npz_ticks).astype(np.uint8))
        files["npz (other tool)"] = foreign
        files["zarr (viform)"] = save_spikes(folder / "s.zarr", RandomStream(dat_ticks))
        print(f"{'file':<18} {'size MB':>8} {'ticks':>6} {'--at':>6} {'checked s':>10} {'plain s':>8} "
              f"{'diff':>7} {'inside':>7} {'peak MB':>8}")
        for name, path in files.items():
            size = sum(p.stat().st_size for p in ([path] if path.is_file() else path.rglob("*")) if p.is_file())
            ticks = dat_ticks if "npz" not in name else npz_ticks
            at = min(a.at, 0.5 * ticks / CLOCK_HZ)
            args = ["reconstruct", str(path), "--method", a.method, "--at", f"{at:g}", "--out", str(folder / "x.png")]
            run(args)  # warm-up (imports, compiled kernels, page cache)
            checked, plain, inside = [], [], []
            for _ in range(a.repeat):  # interleaved, so load changes hit both alike
                with TimedChecks().active() as timer:
                    checked.append(run(args))
                inside.append(timer.seconds / checked[-1])
                with unchecked():
                    plain.append(run(args))
            tracemalloc.start()
            run(args)
            peak = tracemalloc.get_traced_memory()[1] / 1e6
            tracemalloc.stop()
            tc, tp = statistics.median(checked), statistics.median(plain)
            print(f"{name:<18} {size / 1e6:>8.1f} {ticks:>6} {at:>6.3g} {tc:>10.3f} {tp:>8.3f} "
                  f"{(tc - tp) / tc:>7.1%} {statistics.median(inside):>7.1%} {peak:>8.1f}")
    print("diff = (checked − plain) / checked, medians of interleaved runs; inside = time inside the checks "
          "(CRC-32s, the zip-CRC pass) / the run's time, median. Goal: ≤ 20 % of reconstruct --at's time")


if __name__ == "__main__":
    main_bench()
