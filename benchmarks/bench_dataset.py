"""Dataset conversion throughput: clips/s and pixel-ticks/s on 1 and 2 local dask workers.

A set of synthetic frame-folder clips (random textures sliding 1 px per frame) is converted
three times in this process: serially without dask (the plain reference: the same
:func:`viform.datasets.build.convert_clip` in a loop, numba on one thread), then with
``build_dataset`` on a LocalCluster of 1 worker and of 2 workers (processes, 1 thread each).
Each cluster is warmed up on a one-clip set first, so the rates count conversion, not start-up
(the start-up time is printed separately). Prints clips/s, pixel-ticks/s, the ratio to the
reference, the speed-up of 2 workers over 1, the conversion rate per CPU-second of a worker
(what one free core would give: not skewed by other load on a shared machine), the workers'
peak resident memory, the load average, and checks that the three runs wrote identical bits.

Run:  python benchmarks/bench_dataset.py [--clips 8] [--frames 10] [--height 125] [--width 200] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import tempfile
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np


def make_clips(root: Path, clips: int, frames: int, height: int, width: int) -> Path:
    rng = np.random.default_rng(0)
    for c in range(clips):
        folder = root / f"clip{c:03d}"
        folder.mkdir(parents=True)
        base = rng.integers(0, 256, (height, width)).astype(np.uint8)
        for k in range(frames):
            iio.imwrite(folder / f"{k:08d}.png", np.roll(base, k, axis=1))
    return root


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _files(root: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted((root / "spike").glob("*.dat"))}


def run_cluster(n_workers: int, src: Path, warm_src: Path, out: Path, settings, block_ticks: int) -> dict:
    from distributed import Client, LocalCluster

    from viform.datasets import build_dataset

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    try:
        # first task on each worker imports viform and loads the compiled kernels
        build_dataset(warm_src, out.with_name(out.name + "-warm"), settings, client=client, progress=False,
                      block_ticks=block_ticks)
        startup = time.perf_counter() - t0
        summary = build_dataset(src, out, settings, client=client, progress=False, block_ticks=block_ticks)
        peaks = client.run(_peak_rss_mb)
    finally:
        client.close()
        cluster.close()
    summary["startup_s"] = startup
    summary["worker_peak_rss_mb"] = max(peaks.values())
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=8)
    parser.add_argument("--frames", type=int, default=10, help="frames per clip (at 1 kHz: 40 ticks a frame)")
    parser.add_argument("--height", type=int, default=125)
    parser.add_argument("--width", type=int, default=200)
    parser.add_argument("--block-ticks", type=int, default=4096)
    parser.add_argument("--json", dest="json_path", default=None)
    args = parser.parse_args()

    from viform.datasets import convert_serially, make_settings

    settings = make_settings(height=args.height, width=args.width, frame_rate_hz=1000.0, gt_every=5)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-dataset-") as tmp:
        tmp = Path(tmp)
        src = make_clips(tmp / "src", args.clips, args.frames, args.height, args.width)
        warm = make_clips(tmp / "warm", 2, 2, args.height, args.width)
        convert_serially(warm, tmp / "warm-serial", settings)  # compile / load kernels here first
        serial = convert_serially(src, tmp / "serial", settings, block_ticks=args.block_ticks)
        serial["worker_peak_rss_mb"] = _peak_rss_mb()
        one = run_cluster(1, src, warm, tmp / "one", settings, args.block_ticks)
        two = run_cluster(2, src, warm, tmp / "two", settings, args.block_ticks)
        same = _files(tmp / "serial") == _files(tmp / "one") == _files(tmp / "two")
    load_after = os.getloadavg()

    pixel_ticks = serial["pixel_ticks_converted"]
    print(f"{args.clips} clips of {args.frames} frames at 1 kHz, {args.width}×{args.height} px, 40 kHz clock: "
          f"{pixel_ticks / args.clips:.3g} pixel-ticks a clip")
    print(f"load average (1 min) before {load_before[0]:.2f}, after {load_after[0]:.2f}; {os.cpu_count()} CPU cores")
    print(f"{'run':<18}{'clips/s':>9}{'Mpixel-ticks/s':>16}{'vs serial':>11}{'Mpx-ticks/CPU-s':>17}"
          f"{'start-up s':>12}{'peak RSS MB':>13}")
    for name, s in (("serial, no dask", serial), ("dask, 1 worker", one), ("dask, 2 workers", two)):
        print(f"{name:<18}{s['clips_per_s']:>9.3g}{s['pixel_ticks_per_s'] / 1e6:>16.4g}"
              f"{s['pixel_ticks_per_s'] / serial['pixel_ticks_per_s']:>11.3g}"
              f"{pixel_ticks / s['cpu_seconds'] / 1e6:>17.4g}"
              f"{s.get('startup_s', 0.0):>12.3g}{s['worker_peak_rss_mb']:>13.4g}")
    speedup = two["pixel_ticks_per_s"] / one["pixel_ticks_per_s"]
    print(f"speed-up, 2 workers over 1: {speedup:.3g}× (goal ≥ 1.7× on 2 free cores)")
    print(f"identical bits in all three runs: {same}")
    if args.json_path:
        with open(args.json_path, "w") as f:
            json.dump({"args": vars(args), "load_before": load_before, "load_after": load_after,
                       "serial": serial, "one_worker": one, "two_workers": two, "speedup_2_over_1": speedup,
                       "identical_bits": same}, f, indent=2, default=str)


if __name__ == "__main__":
    main()
