"""The designer's standard sweep on the demo's dilemma scene: wall time, CPU-seconds, speed-up on 2 workers.

The sweep (``viform sweep dilemma`` with no ``--sensor``): the spike camera's 16 threshold levels ×
2 clocks (20 / 40 kHz) and 20 settings of each frame sensor (plus each sensor's default), at
64×128 pixels, 40 ms. It is run into fresh folders with 1 and with 2 local dask workers (the
LocalCluster's start-up included in the wall time, as a user sees it) and, as the plain
reference, in this process without dask. Printed: points, wall s, CPU-seconds of the points
(each worker process's CPU time over its points, summed) and of this process, the load average
before and after, and the speed-up of 2 workers over 1. The metrics of the runs are checked
identical.
Run: ``python benchmarks/bench_sweep.py [--workers 1,2] [--serial]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from viform.measure.sweep import make_plan, sweep


def load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", default="1,2", help="worker counts to run, comma-separated")
    ap.add_argument("--serial", action="store_true", help="also run in this process without dask")
    ap.add_argument("--height", type=int, default=64)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--duration", type=float, default=0.04)
    args = ap.parse_args()
    plan = make_plan("dilemma", height=args.height, width=args.width, duration_s=args.duration,
                     require="dr_captured_db>=122,edge_width_px<=2")
    print(f"standard sweep: {len(plan.points)} points on dilemma {args.height}×{args.width}, "
          f"{args.duration * 1e3:g} ms; {os.cpu_count()} CPUs; load {load()}")
    runs = [("in-process", 0)] if args.serial else []
    runs += [(f"{n} worker{'s' if n > 1 else ''}", n) for n in map(int, args.workers.split(","))]
    results = {}
    for name, workers in runs:
        with tempfile.TemporaryDirectory() as tmp:
            before = load()
            wall, cpu = time.perf_counter(), time.process_time()
            doc = sweep(plan, tmp, workers=workers, progress=False)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            results[name] = (wall, doc)
            print(f"{name:<12} {doc['n_points']} points  wall {wall:7.1f} s (points {doc['seconds']:.1f} s)  "
                  f"CPU-s of the points {doc['cpu_seconds']:6.1f}  of this process {cpu:6.1f}  "
                  f"load {before} → {load()}", flush=True)
    names = list(results)
    ref = results[names[0]][1]["records"]
    for name in names[1:]:
        for a, b in zip(ref, results[name][1]["records"], strict=True):
            for k, v in a["metrics"].items():
                w = b["metrics"][k]
                same = (v == w) or (isinstance(v, float) and np.isnan(v) and np.isnan(w))
                assert same, (name, a["label"], k, v, w)
    print("metrics identical across runs: yes")
    one = [n for n in names if n.startswith("1 ")]
    two = [n for n in names if n.startswith("2 ")]
    if one and two:
        print(f"speed-up of 2 workers over 1: {results[one[0]][0] / results[two[0]][0]:.2f}× (wall)")
    print("answer:", *results[names[-1]][1]["answer"]["sentences"], sep="\n  ")


if __name__ == "__main__":
    main()
