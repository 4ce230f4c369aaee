"""Sweeps that scale: a 32-point sweep in this process and on 1 and 2 dask workers — wall, CPU, ratios.

The sweep (default): the spike camera's 16 threshold levels × 2 clocks (20 / 40 kHz) on the demo's
dilemma scene, 128×64 pixels, 40 ms — 32 points (``--standard``: the designer's standard sweep of
every sensor instead). It is run into fresh folders in this process without dask (the plain
reference) and with 1 and 2 local dask workers (the LocalCluster's start-up included in the wall
time, as a user sees it). Printed per run: wall s; CPU-seconds of this process and of its child
processes (the dask workers, counted when they exit; those forked from multiprocessing's fork server
through it, which is stopped after each run so that the next starts a fresh one as a command does:
``--keep-forkserver`` keeps it), and their sum; the sum of
the points' own CPU-seconds; the per-point overhead (the run's CPU beyond the points', per point);
peak resident memory (this process; the largest child); the load average before and after. Then
the ratios to the in-process run, wall and CPU, and the check that every run's metrics and images
are identical (across worker counts and repetitions). ``--repeat N`` runs the list N times, every
other time in reverse order, so that a change of the machine's load does not favour one side. Each kind
of run is first run once uncounted (``--no-warmup`` to skip it): the first run in this process pays its
imports and numba's cache loads (0.52 CPU-s/point against 0.38 warm), which would flatter whichever
side runs second.

The machine may be shared: the load is printed beside every figure, and the CPU-seconds ratio
(which a busy machine changes little) beside the wall ratio. The goal (≤ 0.6× the in-process wall
with 2 workers) is stated for an idle 2-core machine.

Run: ``python benchmarks/bench_sweep.py [--workers 0,1,2] [--repeat 2] [--height 64 --width 128 --duration 0.04]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time

import numpy as np

from viform.measure.sweep import load_images, make_plan, run, sweep


def load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def stop_forkserver() -> None:
    """Stop multiprocessing's fork server (the sweep's workers are forked from it,
    :data:`viform._parallel.WORKER_START`) and wait for it: its CPU and its children's then count
    in this process's RUSAGE_CHILDREN, and the next run starts a fresh one, as a command does."""
    import multiprocessing.forkserver

    multiprocessing.forkserver._forkserver._stop()


def _cpu() -> tuple[float, float]:
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime


def _peak_mib() -> tuple[float, float]:
    """Peak resident memory, MiB: this process, and the largest of its children that have exited."""
    return (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)


def run_once(plan, workers: int, out: str, keep_forkserver: bool = False) -> dict:
    if not keep_forkserver:
        stop_forkserver()
    before = load()
    (me0, kids0), wall = _cpu(), time.perf_counter()
    doc = sweep(plan, out, workers=workers, progress=False)
    wall = time.perf_counter() - wall
    if not keep_forkserver:
        stop_forkserver()  # (after the wall time) its CPU and its workers' now count as children's
    me1, kids1 = _cpu()
    me, kids = me1 - me0, kids1 - kids0
    n = len(plan.points)
    overhead = (me + kids - doc["cpu_seconds"]) / n
    peak_me, peak_kids = _peak_mib()
    print(f"{workers} worker{'s' if workers != 1 else ''}{' (in this process)' if workers == 0 else ''}: "
          f"wall {wall:6.1f} s  CPU-s: this process {me:5.1f} + children {kids:5.1f} = {me + kids:5.1f}; "
          f"points' own {doc['cpu_seconds']:5.1f} ({doc['cpu_seconds'] / n:.3f}/point); "
          f"overhead {overhead:+.3f} CPU-s/point; peak memory {peak_me:.0f} MiB here, {peak_kids:.0f} MiB largest "
          f"child; load {before} → {load()}", flush=True)
    return {"wall": wall, "cpu": me + kids, "doc": doc, "out": out}


def plain_processes_once(plan, n: int) -> dict:
    """The same points on ``n`` plain Python processes (a spawn ProcessPoolExecutor running the sweep's own
    guided batches, no dask, nothing stored): what any process split costs on this machine, to tell
    dask's share of the overhead from the machine's."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    before = load()
    (me0, kids0), wall = _cpu(), time.perf_counter()
    with ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(run.run_points, plan.context, b) for b in run.batches(plan.points, n)]
        results = {r["record"]["point_id"]: r for f in futures for r in f.result()}
    wall = time.perf_counter() - wall
    me1, kids1 = _cpu()
    me, kids = me1 - me0, kids1 - kids0
    own = sum(r["record"]["cpu_seconds"] for r in results.values())
    print(f"{n} plain processes (no dask): wall {wall:6.1f} s  CPU-s: this process {me:5.1f} + children {kids:5.1f} = "
          f"{me + kids:5.1f}; points' own {own:5.1f} ({own / len(plan.points):.3f}/point); overhead "
          f"{(me + kids - own) / len(plan.points):+.3f} CPU-s/point; load {before} → {load()}", flush=True)
    return {"wall": wall, "cpu": me + kids, "results": results}


def same_points(ref: dict, run: dict) -> None:
    """Every point's metrics and images of ``run`` equal ``ref``'s (NaN equals NaN)."""
    for a, b in zip(ref["doc"]["records"], run["doc"]["records"], strict=True):
        assert a["point_id"] == b["point_id"]
        for k, v in a["metrics"].items():
            u = b["metrics"][k]
            assert v == u or (isinstance(v, float) and np.isnan(v) and np.isnan(u)), (a["label"], k, v, u)
        assert np.array_equal(load_images(ref["out"], a["point_id"]), load_images(run["out"], b["point_id"]),
                              equal_nan=True), a["label"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", default="0,1,2", help="worker counts to run, comma-separated (0: in this process)")
    ap.add_argument("--height", type=int, default=64)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--duration", type=float, default=0.04)
    ap.add_argument("--standard", action="store_true", help="the standard sweep of every sensor (158 points)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run the list this many times, in reverse order every other time; ratios per repetition")
    ap.add_argument("--plain", type=int, default=0,
                    help="also run the points on this many plain processes (no dask) in each repetition")
    ap.add_argument("--no-warmup", action="store_true",
                    help="count the first run of each kind too (it pays this process's imports and numba cache loads)")
    ap.add_argument("--keep-forkserver", action="store_true",
                    help="keep the workers' fork server between runs (its start then paid once, by the warm-up)")
    ap.add_argument("--one-per-task", action="store_true",
                    help="one point per dask task (no guided batches), to measure what batching saves")
    args = ap.parse_args()
    if args.one_per_task:
        run.GUIDED_SHARE = 0
    size = dict(height=args.height, width=args.width, duration_s=args.duration)
    if args.standard:
        plan = make_plan("dilemma", require="dr_captured_db>=122,edge_width_px<=2", **size)
    else:
        plan = make_plan("dilemma", ["spikeone"], ["spikeone:threshold_level=all", "spikeone:clock_hz=20e3,40e3"],
                         require="dr_captured_db>=60,time_resolution_s<=0.000333", **size)
    counts = list(map(int, args.workers.split(",")))
    print(f"sweep: {len(plan.points)} points on dilemma {args.height}×{args.width}, {args.duration * 1e3:g} ms; "
          f"{'one point per task' if args.one_per_task else 'guided batches'}; {os.cpu_count()} CPUs; "
          f"load {load()}", flush=True)
    last = None
    with tempfile.TemporaryDirectory() as tmp:
        if not args.no_warmup:  # every measured run warm: this process's imports and numba cache loads paid here
            print("warm-up (not counted):", flush=True)
            for workers in counts:
                run_once(plan, workers, os.path.join(tmp, f"warm{workers}"), args.keep_forkserver)
            if args.plain:
                plain_processes_once(plan, args.plain)
            print("measured:", flush=True)
        for rep in range(args.repeat):
            results = {}
            for workers in counts if rep % 2 == 0 else counts[::-1]:
                results[workers] = run_once(plan, workers, os.path.join(tmp, f"r{rep}w{workers}"),
                                            args.keep_forkserver)
            ref_name = counts[0]
            ref = results[ref_name]
            if args.plain:
                plain = plain_processes_once(plan, args.plain)
                for r in ref["doc"]["records"]:
                    got = plain["results"][r["point_id"]]
                    assert got["record"]["metrics"].keys() == r["metrics"].keys()
                    assert all(v == got["record"]["metrics"][k] or (isinstance(v, float) and np.isnan(v))
                               for k, v in r["metrics"].items()), r["label"]
                    assert np.array_equal(load_images(ref["out"], r["point_id"]), got["images"], equal_nan=True)
                print(f"  repetition {rep + 1}: {args.plain} plain processes / {ref_name}: wall "
                      f"{plain['wall'] / ref['wall']:.2f}×, CPU-s {plain['cpu'] / ref['cpu']:.2f}×", flush=True)
            for w in counts[1:]:
                same_points(ref, results[w])
                print(f"  repetition {rep + 1}: {w} worker{'s' if w != 1 else ''} / {ref_name}: "
                      f"wall {results[w]['wall'] / ref['wall']:.2f}×, CPU-s {results[w]['cpu'] / ref['cpu']:.2f}×",
                      flush=True)
            if last is not None:
                same_points(last, ref)
            last = ref
    print("metrics and images identical across runs: yes")
    print("answer:", *last["doc"]["answer"]["sentences"], sep="\n  ")


if __name__ == "__main__":
    main()
