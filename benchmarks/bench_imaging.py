"""Read ``reds_sim_400x250.dat`` and image every tick by accumulation and by interval, and chosen instants by interval.

viform's streaming, bounded-memory imaging (``sliding_accumulation``, ``interval_frames``)
against a straightforward NumPy implementation on the whole array (cumulative sums for the
window; ``maximum.accumulate`` / reversed ``minimum.accumulate`` for the previous and next
spike), run in the same process; both include reading and unpacking the file. The outputs
are checked equal before timing.

Single instants (``interval_ticks``, what ``interval_image``, ``viform compare`` and the sweeps
use): 16 instants of a 40 ms SpikeOne and a Q = 100 e⁻ shot of the demo scene, held in memory,
against the plain NumPy search per instant (``argmax`` of the reversed and forward spikes from
the instant on), with the peak memory each takes above its input (tracemalloc).
Run: ``python benchmarks/bench_imaging.py``.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np

from viform.imaging import interval_frames, interval_ticks, sliding_accumulation
from viform.stream.io import open_spikes

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "spike" / "reds_sim_400x250.dat"
WINDOW = 41


def numpy_accumulation(path) -> np.ndarray:
    raw = np.fromfile(path, dtype=np.uint8).reshape(-1, 12_500)
    spikes = np.unpackbits(raw, axis=1, bitorder="little").reshape(-1, 250, 400)[:, ::-1]
    cumulative = np.cumsum(spikes, axis=0, dtype=np.int32)
    counts = cumulative.copy()
    counts[WINDOW:] -= cumulative[:-WINDOW]
    return counts


def numpy_interval(path) -> np.ndarray:
    raw = np.fromfile(path, dtype=np.uint8).reshape(-1, 12_500)
    spikes = np.unpackbits(raw, axis=1, bitorder="little").reshape(-1, 250, 400)[:, ::-1].astype(bool)
    n = spikes.shape[0]
    ticks = np.arange(n)[:, None, None]
    prev = np.maximum.accumulate(np.where(spikes, ticks, -1), axis=0)
    later = np.where(spikes, ticks, n)
    later = np.concatenate([later[1:], np.full((1,) + later.shape[1:], n)])  # next spike strictly after k
    nxt = np.minimum.accumulate(later[::-1], axis=0)[::-1]
    return (nxt - prev).astype(np.int32)


def viform_accumulation(path) -> np.ndarray:
    source = open_spikes(path, 250, 400)
    return np.concatenate([c for _, c in sliding_accumulation(source, WINDOW, block_ticks=64)])


def viform_interval(path) -> np.ndarray:
    source = open_spikes(path, 250, 400)
    return np.concatenate([t for _, t in interval_frames(source, block_ticks=64, lookahead_ticks=source.n_ticks)])


def numpy_instants(spikes: np.ndarray, ticks) -> np.ndarray:
    """τ at each of ``ticks``: per instant, the last spike at or before it and the first after it, by argmax."""
    n = spikes.shape[0]
    flat = spikes.reshape(n, -1)
    out = np.empty((len(ticks), flat.shape[1]), np.int64)
    for m, k in enumerate(ticks):
        before = flat[k::-1]
        prev = np.where(before.any(axis=0), k - before.argmax(axis=0), -1)
        after = flat[k + 1:]
        nxt = np.where(after.any(axis=0), k + 1 + after.argmax(axis=0), n) if k + 1 < n else np.full(flat.shape[1], n)
        out[m] = nxt - prev
    return out.reshape((len(ticks),) + spikes.shape[1:])


def instants_rows(repeats: int) -> list:
    """interval_ticks at 16 instants against :func:`numpy_instants`, on the demo scene shot by two sensors."""
    from viform.light.catalog import builtin_scene
    from viform.sensors.catalog import make_sensor

    rows = []
    scene = builtin_scene("dilemma")
    for sensor in ("spikeone", "spike"):
        stream = make_sensor(sensor).capture(scene, 0.04, seed=1)
        ticks = np.linspace(0, stream.n_ticks - 1, 16).astype(int)
        def ours(stream=stream, ticks=ticks):
            return interval_ticks(stream, ticks)[0]

        def ref(stream=stream, ticks=ticks):
            return numpy_instants(stream.spikes, ticks)

        assert np.array_equal(ours(), ref()), f"{sensor}: interval_ticks and the NumPy search disagree"
        times, peaks = {}, {}
        for name, fn in (("viform", ours), ("numpy", ref)):
            best = np.inf
            for _ in range(repeats):
                started = time.process_time()
                fn()
                best = min(best, time.process_time() - started)
            tracemalloc.start()
            fn()
            peaks[name] = tracemalloc.get_traced_memory()[1] / 2**20
            tracemalloc.stop()
            times[name] = best
        rows.append((f"instants, {sensor}", len(ticks) / times["viform"], len(ticks) / times["numpy"]))
        label = "interval, 16 instants, " + sensor
        print(f"{label:>30}: viform {len(ticks) / times['viform']:8.1f} instants per CPU-s, "
              f"NumPy {len(ticks) / times['numpy']:8.1f}, ratio {times['numpy'] / times['viform']:.1f}×; peak memory "
              f"{peaks['viform']:.1f} vs {peaks['numpy']:.1f} MiB (firing {stream.spikes.mean():.3f} per pixel-tick, "
              f"{stream.n_ticks} ticks of 400×250 in memory)", flush=True)
    return rows


def best_time(fn, repeats):
    best, result = np.inf, None
    for _ in range(repeats):
        started = time.perf_counter()
        result = fn(DATA)
        best = min(best, time.perf_counter() - started)
    return best, result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    rows = instants_rows(args.repeats)
    if not DATA.exists():
        print(f"shared data not found: {DATA} (every-tick rows skipped)")
        return rows
    for name, ours, reference in (("accumulation (41-tick window)", viform_accumulation, numpy_accumulation),
                                  ("interval", viform_interval, numpy_interval)):
        ours(DATA)  # compile
        t_ours, a = best_time(ours, args.repeats)
        t_ref, b = best_time(reference, args.repeats)
        assert np.array_equal(a, b), f"{name}: viform and the NumPy reference disagree"
        frames = a.shape[0]
        rows.append((name, frames / t_ours, frames / t_ref))
        print(f"{name:>30}: viform {frames / t_ours:8.0f} frames/s, NumPy {frames / t_ref:8.0f} frames/s, "
              f"ratio {t_ref / t_ours:.1f}× ({frames} frames of 400×250, read from .dat)")
    return rows


if __name__ == "__main__":
    main()
