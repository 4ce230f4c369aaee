"""Read ``reds_sim_400x250.dat`` and image every tick by accumulation and by interval.

viform's streaming, bounded-memory imaging (``sliding_accumulation``, ``interval_frames``)
against a straightforward NumPy implementation on the whole array (cumulative sums for the
window; ``maximum.accumulate`` / reversed ``minimum.accumulate`` for the previous and next
spike), run in the same process; both include reading and unpacking the file. The outputs
are checked equal before timing. Run: ``python benchmarks/bench_imaging.py``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from viform.imaging import interval_frames, sliding_accumulation
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
    if not DATA.exists():
        raise SystemExit(f"shared data not found: {DATA}")
    rows = []
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
