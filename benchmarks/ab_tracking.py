"""The tracker of a git revision against this tree's, alternated in one process: wall and CPU ratios, same tracks.

On a shared machine a before/after figure from two separate runs mostly measures the load between them.
Here both trackers run in the same process, one after the other, in alternating order over ``--rounds``
rounds, and the medians are compared. The revision's ``viform/vision/tracking.py`` is loaded as a module
of its own: it runs on this tree's compiled kernels, readers and parameters, so what is compared is
the tracker module itself, which is what changes when the tracker is optimized. Every run's result
(MOTChallenge rows, step times, spike counts, detections) must equal the other's bit for bit, or the
command stops; a speed-up that changes the tracks is not one.

Run: ``python benchmarks/ab_tracking.py CLIP.dat [CLIP.dat ...] [--rev main~1] [--every 40,10] [--rounds 6]``
(clips as ``bench_tracking.py --streams DIR`` keeps them). Prints, per clip and step, ticks per second
(wall) and per CPU-second for each, the ratios of the medians (this tree ÷ the revision: above 1 is
faster), and the load average.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np

from viform.stream.io import open_spikes
from viform.vision import tracking

ROOT = Path(__file__).resolve().parents[1]


def tracker_of(rev: str) -> types.ModuleType:
    """``viform.vision.tracking`` as it is at git revision ``rev``, as a module of its own."""
    text = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:src/viform/vision/tracking.py"],
                          check=True, capture_output=True, text=True).stdout
    module = types.ModuleType(f"tracking_at_{rev}")
    module.__file__ = f"{rev}:src/viform/vision/tracking.py"
    sys.modules[module.__name__] = module  # (dataclasses look their module up)
    exec(compile(text, module.__file__, "exec"), module.__dict__)
    return module


def same(a, b) -> bool:
    return (np.array_equal(a.rows, b.rows) and np.array_equal(a.times_s, b.times_s)
            and np.array_equal(a.spike_counts, b.spike_counts) and a.detections == b.detections)


def compare(path: str, every: int, trackers: dict, rounds: int) -> None:
    results = {name: module.track_spikes(open_spikes(path), every) for name, module in trackers.items()}
    first, second = results.values()
    if not same(first, second):
        raise SystemExit(f"{path}, every {every}: the two trackers' results differ; no speed figure is printed")
    wall = {name: [] for name in trackers}
    cpu = {name: [] for name in trackers}
    names = list(trackers)
    for r in range(rounds):
        for name in names if r % 2 == 0 else names[::-1]:
            c, w = time.process_time(), time.perf_counter()
            trackers[name].track_spikes(open_spikes(path), every)
            wall[name].append(time.perf_counter() - w)
            cpu[name].append(time.process_time() - c)
    n = open_spikes(path).n_ticks
    print(f"{Path(path).name}, every {every}: {rounds} rounds alternated, load {os.getloadavg()[0]:.2f}; "
          f"identical results")
    for name in names:
        print(f"  {name:>12}: {n / statistics.median(wall[name]):9,.0f} ticks/s (median; best "
              f"{n / min(wall[name]):,.0f}), {n / statistics.median(cpu[name]):9,.0f} ticks/CPU-s")
    old, new = names
    print(f"  this tree ÷ {old}: wall ×{statistics.median(wall[old]) / statistics.median(wall[new]):.3f}, "
          f"CPU ×{statistics.median(cpu[old]) / statistics.median(cpu[new]):.3f}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clips", nargs="+", help=".dat files")
    ap.add_argument("--rev", default="HEAD", help="git revision of the tracker to compare with (default HEAD)")
    ap.add_argument("--every", default="40,10", help="output steps, ticks, comma-separated")
    ap.add_argument("--rounds", type=int, default=6)
    args = ap.parse_args(argv)
    trackers = {args.rev: tracker_of(args.rev), "this tree": tracking}
    for path in args.clips:
        for every in map(int, args.every.split(",")):
            compare(path, every, trackers, args.rounds)


if __name__ == "__main__":
    main()
