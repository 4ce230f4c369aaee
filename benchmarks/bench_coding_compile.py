"""Cold compile cost of the coding kernels, per ``.vfc`` format version (issue 38 item 7: the test suite's budget).

For each version, a fresh process with an empty numba cache (``NUMBA_CACHE_DIR``) writes and reads back a
tiny stream (120 ticks of 5 × 6 pixels) in strict and in statistical mode, and prints the CPU-seconds of
each first encode and decode — what the first coding test of a pytest worker pays on a fresh clone. The
same process first compiles a plain reference kernel (a loop summing an array), so each figure is also
given as a ratio to numba's cost of compiling one small function on the same machine at the same moment.
A second process on the now filled cache gives the cost of loading the cached kernels.

Run: ``python benchmarks/bench_coding_compile.py [--versions 6,5] [--json out.json]`` (CPU-seconds of the
child processes, ``time.process_time``; the load is printed before and after).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

_CHILD = r"""
import json, os, sys, time
t0 = time.process_time()
import numpy as np
from numba import njit

@njit
def _plain_sum(a):
    s = 0
    for i in range(a.size):
        s += a[i]
    return s

t1 = time.process_time()
_plain_sum(np.arange(10, dtype=np.int64))
ref = time.process_time() - t1
from viform.coding.aer_file import CodedFile, encode_source
from viform.stream.container import SpikeStream
version = int(sys.argv[1])
folder = sys.argv[2]
rng = np.random.default_rng(3)
spikes = rng.random((120, 5, 6)) < 0.2
stream = SpikeStream(spikes, 1000.0, 50.0)
out = {"reference_cpu_s": ref}
for mode in ("strict", "statistical"):
    path = os.path.join(folder, f"v{version}-{mode}.vfc")
    t1 = time.process_time()
    encode_source(stream, path, mode, segment_ticks=32, version=version)
    t2 = time.process_time()
    back = CodedFile(path).read_ticks(0, 120)
    t3 = time.process_time()
    if mode == "strict":
        assert np.array_equal(back, spikes)
    out[f"{mode}_encode_cpu_s"] = t2 - t1
    out[f"{mode}_decode_cpu_s"] = t3 - t2
out["total_cpu_s"] = time.process_time() - t0
print(json.dumps(out))
"""


def _load() -> str:
    return " / ".join(f"{x:.1f}" for x in os.getloadavg())


def run_version(version: int) -> dict:
    """Cold and warm CPU-seconds of version ``version``'s first encode/decode, each in a fresh process."""
    row = {"version": version}
    with tempfile.TemporaryDirectory(prefix="viform-compile-") as folder:
        env = {**os.environ, "NUMBA_CACHE_DIR": os.path.join(folder, "numba"), "VIFORM_THREADS": "1"}
        for phase in ("cold", "warm"):
            proc = subprocess.run([sys.executable, "-c", _CHILD, str(version), folder], capture_output=True,
                                  text=True, env=env, check=False)
            if proc.returncode != 0:
                raise RuntimeError(proc.stderr[-2000:])
            row[phase] = json.loads(proc.stdout.strip().splitlines()[-1])
    return row


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--versions", default="6,5,4,3,2,1", help="comma-separated format versions (default: all)")
    parser.add_argument("--json", help="write the rows here")
    args = parser.parse_args(argv)
    versions = [int(v) for v in args.versions.split(",")]
    print(f"load before: {_load()} (1, 5, 15 min); CPU-seconds per child process, fresh numba cache per version")
    print("| version | strict encode | strict decode | statistical encode | statistical decode | total (cold) | "
          "× one small kernel | total (cache loaded) |")
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    t0 = time.perf_counter()
    for v in versions:
        row = run_version(v)
        rows.append(row)
        c, w = row["cold"], row["warm"]
        print(f"| {v} | {c['strict_encode_cpu_s']:.1f} | {c['strict_decode_cpu_s']:.1f} | "
              f"{c['statistical_encode_cpu_s']:.1f} | {c['statistical_decode_cpu_s']:.1f} | {c['total_cpu_s']:.1f} | "
              f"{c['total_cpu_s'] / max(c['reference_cpu_s'], 1e-9):.0f}× ({c['reference_cpu_s']:.2f} s) | "
              f"{w['total_cpu_s']:.1f} |", flush=True)
    print(f"load after: {_load()}; wall {time.perf_counter() - t0:.0f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
