"""First-spike coding (seed 000 §5.2) against the best general-purpose compressors, per stream.

For every stream: the packed raw bits (1 bit per pixel per tick), xz -9 and zstd -19 on both byte
layouts a generic tool could be given — time-major (the camera's ``.dat``: one frame of packed
bits after another) and pixel-major (each pixel's bits over time packed together) — and each
``.vfc`` mode: size, ratio to raw and to the best generic result, bits per spike, encode and decode
speed (Mspikes/s) and peak Python-visible memory (tracemalloc), and for the lossy modes the
distortion a user sees: PSNR of TFP (spike count in a 64-tick window) and interval (1/ISI) images
against the same images of the lossless stream, per tolerance k. Simulated streams (static and
moving scenes, Q from 100 to 10⁴ e⁻, with and without the sensor noise model — gain and dark
current spread, hot pixels) also get the *entropy floor*: the bits per spike that even a coder
knowing each pixel's exact light needs, because of shot noise (seed 000 §5.1: the interval is
Gamma(Q) distributed; rounded to the clock).

The time-precision row (seed 000 §5.2: "first-spike coding raises the time precision with almost
no more data") codes one static scene at 20, 40, 80, 160 and 320 kHz and prints the size of each
mode relative to 20 kHz; ``--figure PATH`` draws it.

``--corpus`` codes the evaluation corpus (the shared files and every built-in scene at three Q and two
clocks), split once by a rule written here into a tuning and a held-out half, with the default version and
version 5 and reports per stream: size vs raw, vs the best generic coder (xz -9, zstd -19, both layouts),
vs version 5, bits per spike, and encode and decode speed in Mspikes per CPU-second (all threads of this
process) of both versions and of zstd -19 and xz -9, measured in the same process; then per half how many
streams the default makes larger than version 5, and the speeds over the shared files (the goal's streams).

Run:  python benchmarks/bench_coding.py [--quick] [--json out.json] [--figure docs/figures/x.png] [--corpus]
"""

from __future__ import annotations

import argparse
import lzma
import os
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import zstandard

from viform.coding.aer_file import VERSION, CodedFile, coding_threads, encode_source
from viform.stream.container import SpikeStream

# the shared data beside the checkout (../shared), or beside a worktree's parent folder
DATA = next((d for d in (Path(__file__).resolve().parents[k] / "shared" / "data" / "spike" for k in (2, 3))
             if d.exists()), Path(__file__).resolve().parents[2] / "shared" / "data" / "spike")
K_VALUES = (1.0, 2.0, 4.0)


# ---------------------------------------------------------------------------- generic coders

def layouts(spikes: np.ndarray) -> dict:
    t = spikes.shape[0]
    flat = spikes.reshape(t, -1)
    return {"time-major": np.packbits(flat, axis=1, bitorder="little").tobytes(),
            "pixel-major": np.packbits(np.ascontiguousarray(flat.T), axis=1).tobytes()}


def generic(spikes: np.ndarray, n_spikes: int) -> dict:
    out = {}
    for lay, data in layouts(spikes).items():
        for name, fn in (("xz-9", lambda b: lzma.compress(b, preset=9)),
                         ("zstd-19", lambda b: zstandard.ZstdCompressor(level=19).compress(b))):
            t0 = time.perf_counter()
            n = len(fn(data))
            dt = time.perf_counter() - t0
            out[f"{name} {lay}"] = {"bytes": n, "ratio_vs_raw": len(data) / n,
                                    "encode_mspikes_per_s": n_spikes / dt / 1e6}
    return out


# ---------------------------------------------------------------------------- images for distortion

def tfp_images(spikes: np.ndarray, probes, window: int = 64) -> np.ndarray:
    """Spike count in a window around each probe tick / window (spikes per tick)."""
    t = spikes.shape[0]
    out = []
    for k in probes:
        a, b = max(0, k - window // 2), min(t, k + window // 2)
        out.append(spikes[a:b].sum(0) / (b - a))
    return np.array(out)


def interval_images(spikes: np.ndarray, probes) -> np.ndarray:
    """1/τ (spikes per tick) of the interval holding each probe tick; NaN where an end cuts it."""
    t = spikes.shape[0]
    flat = spikes.reshape(t, -1)
    idx = np.arange(t)[:, None]
    last = np.maximum.accumulate(np.where(flat, idx, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(flat, idx, t)[::-1], axis=0)[::-1]
    out = np.full((len(probes), flat.shape[1]), np.nan)
    for m, k in enumerate(probes):
        a = last[k]
        b = nxt[k + 1] if k + 1 < t else np.full(flat.shape[1], t)
        ok = (a >= 0) & (b < t)
        out[m, ok] = 1.0 / (b[ok] - a[ok])
    return out.reshape((len(probes),) + spikes.shape[1:])


def psnr_db(x, ref) -> float:
    ok = np.isfinite(x) & np.isfinite(ref)
    mse = float(np.mean((x[ok] - ref[ok]) ** 2))
    peak = float(np.nanmax(ref))
    return float("inf") if mse == 0 else 10 * np.log10(peak ** 2 / mse)


# ---------------------------------------------------------------------------- entropy floor

def entropy_floor_bits_per_spike(mean_interval_ticks: np.ndarray, q: float, n: int = 4000, seed: int = 0) -> float:
    """A lower bound on the bits per spike of any lossless code of a steady pixel's spike ticks.

    The decoder of a real stream knows less than the exact continuous time of the previous
    crossing; given it (and the exact light), the next spike tick is ⌊φ + G⌋ with G ~ Gamma(Q)
    scaled to the mean interval (seed 000 §5.1) and φ the crossing's phase inside its tick.
    The entropy of that, averaged over φ ~ U[0, 1) and over the pixels, bounds every code from
    below (conditioning on more cannot raise an entropy).
    """
    rng = np.random.default_rng(seed)
    mus = rng.choice(np.asarray(mean_interval_ticks, float).ravel(), 64)
    h = []
    for mu in mus:
        g = rng.gamma(q, mu / q, n)
        hs = []
        for phi in (np.arange(16) + 0.5) / 16:  # the entropy given φ, averaged over φ
            _, c = np.unique(np.floor(phi + g).astype(np.int64), return_counts=True)
            hs.append(-(c / n * np.log2(c / n)).sum())
        h.append(np.mean(hs))
    # per spike: a pixel contributes in proportion to its spike rate 1/μ
    return float(np.average(h, weights=1.0 / mus))


# ---------------------------------------------------------------------------- one stream

def bench_stream(name: str, stream: SpikeStream, tmp: Path, lossy: bool = True, floor=None) -> dict:
    spikes = stream.spikes
    t = spikes.shape[0]
    n_spikes = int(spikes.sum())
    raw = spikes.size / 8
    row = {"stream": name, "shape": list(spikes.shape), "spikes": n_spikes, "raw_bytes": raw,
           "raw_bits_per_spike": 8 * raw / max(1, n_spikes), "generic": generic(spikes, n_spikes)}
    best = min(row["generic"].items(), key=lambda kv: kv[1]["bytes"])
    row["best_generic"] = {"name": best[0], **best[1]}
    if floor is not None:
        row["entropy_floor_bits_per_spike"] = floor
    probes = np.linspace(t * 0.2, t * 0.8, 5).astype(int)
    ref_tfp = tfp_images(spikes, probes)
    ref_iv = interval_images(spikes, probes)
    q = stream.threshold_electrons
    modes = [("strict", "strict", None), ("strict 1 thread", "strict", None), ("strict version 5", "strict", None)]
    if lossy and q is not None:
        modes += [(f"statistical k={k:g}", "statistical", k) for k in K_VALUES]
    if lossy:
        modes.append(("intensity", "intensity", 0.0))
    row["modes"] = {}
    for label, mode, k in modes:
        path = tmp / "s.vfc"
        version = 5 if label.endswith("version 5") else VERSION
        threads = os.environ.get("VIFORM_THREADS")
        if label.endswith("1 thread"):
            os.environ["VIFORM_THREADS"] = "1"
        try:
            tracemalloc.start()
            t0 = time.perf_counter()
            info = encode_source(stream, path, mode, k=k, threshold_electrons=q,
                                 slack_ticks=1 if mode != "strict" else 0, version=version)
            enc_s = time.perf_counter() - t0
            enc_peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            tracemalloc.start()
            t0 = time.perf_counter()
            cf = CodedFile(path)
            dec = np.concatenate([b for _, b in cf.iter_blocks(1024)])
            dec_s = time.perf_counter() - t0
            dec_peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        finally:
            if threads is None:
                os.environ.pop("VIFORM_THREADS", None)
            else:
                os.environ["VIFORM_THREADS"] = threads
        r = {"bytes": info["bytes"], "ratio_vs_raw": raw / info["bytes"],
             "ratio_vs_best_generic": best[1]["bytes"] / info["bytes"],
             "bits_per_spike": 8 * info["bytes"] / max(1, n_spikes),
             "encode_mspikes_per_s": n_spikes / enc_s / 1e6, "decode_mspikes_per_s": n_spikes / dec_s / 1e6,
             "encode_peak_mb": enc_peak / 1e6, "decode_peak_mb": dec_peak / 1e6,
             "lossless": bool(np.array_equal(dec, spikes))}
        if mode != "strict":
            r["psnr_tfp_db"] = psnr_db(tfp_images(dec, probes), ref_tfp)
            r["psnr_interval_db"] = psnr_db(interval_images(dec, probes), ref_iv)
        row["modes"][label] = r
        os.remove(path)
    return row


# ---------------------------------------------------------------------------- simulated streams

def _sensor(q, clock_hz=40e3, noise=False):
    from viform.sensors.spike import SpikeSensor

    extra = {}
    if noise:
        extra = {"gain_spread_fraction": 0.01, "dark_current_spread_fraction": 0.5, "hot_pixel_fraction": 1e-3}
    try:
        return SpikeSensor(threshold_electrons=q, dark_current_e_per_s=20.0, clock_hz=clock_hz, **extra)
    except TypeError:  # an older sensor model without the noise fields
        return SpikeSensor(threshold_electrons=q, dark_current_e_per_s=20.0, clock_hz=clock_hz)


def static_scene(q, size, ticks, clock_hz=40e3, noise=False, interval_range=(2.0, 20.0), seed=0):
    """A still scene whose light gives mean intervals uniform in ``interval_range`` ticks at 40 kHz."""
    from viform.light.scenes import StillScene

    sensor = _sensor(q, clock_hz, noise)
    rng = np.random.default_rng(seed)
    mean_iv = rng.uniform(*interval_range, size)  # ticks at 40 kHz
    e_per_s = q / (mean_iv / 40e3)
    lux = sensor.parameters.optics.lux_from_electrons_per_s(e_per_s)
    s = sensor.capture(StillScene(lux), ticks / clock_hz, seed=1)
    return s, mean_iv * clock_hz / 40e3


def moving_scene(q, size, ticks, speed_px_per_s=400.0, noise=False):
    """A texture translating at ``speed_px_per_s``, bright enough for mean intervals of 2–20 ticks."""
    from viform.light.scenes import TranslatingScene

    sensor = _sensor(q, 40e3, noise)
    e_lo, e_hi = q / (20 / 40e3), q / (2 / 40e3)
    lux_lo = sensor.parameters.optics.lux_from_electrons_per_s(e_lo)
    lux_hi = sensor.parameters.optics.lux_from_electrons_per_s(e_hi)
    scene = TranslatingScene(size[0], size[1], velocity_px_per_s=(speed_px_per_s, 0.0), min_lux=lux_lo,
                             max_lux=lux_hi, period_px=24.0)
    return sensor.capture(scene, ticks / 40e3, seed=1)


def time_precision(quick: bool, tmp: Path) -> list[dict]:
    """Coded size against the clock rate for one static scene (seed 000 §5.2)."""
    size = (48, 48) if quick else (64, 64)
    duration_ticks_20k = 500 if quick else 1000
    rows = []
    for q in (100.0, 1e4):
        for clock in (20e3, 40e3, 80e3, 160e3, 320e3):
            ticks = int(duration_ticks_20k * clock / 20e3)
            # light: mean intervals 2–20 ticks at 20 kHz, the same light at every clock
            s, _ = static_scene(q, size, ticks, clock_hz=clock, interval_range=(4.0, 40.0))
            row = {"threshold_electrons": q, "clock_hz": clock, "raw_bytes": s.spikes.size / 8, "size": list(size),
                   "duration_s": ticks / clock,
                   "spikes": int(s.spikes.sum())}
            for mode, k in (("strict", None), ("statistical", 2.0), ("intensity", 0.0)):
                info = encode_source(s, tmp / "p.vfc", mode, k=k, slack_ticks=0 if mode == "strict" else 1)
                row[mode] = info["bytes"]
            best = min(len(lzma.compress(b, preset=9)) for b in layouts(s.spikes).values())
            row["best xz"] = best
            rows.append(row)
    return rows


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform._io import save_figure

    qs = sorted({r["threshold_electrons"] for r in rows})
    fig, axes = plt.subplots(1, len(qs), figsize=(5.2 * len(qs), 4.2), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, q in zip(axes, qs, strict=True):
        rs = [r for r in rows if r["threshold_electrons"] == q]
        clocks = np.array([r["clock_hz"] for r in rs]) / 1e3
        for key, style in (("raw_bytes", "k--"), ("best xz", "C7-s"), ("strict", "C0-o"),
                           ("statistical", "C1-o"), ("intensity", "C2-o")):
            v = np.array([r[key] for r in rs], float)
            label = {"raw_bytes": "raw bits", "best xz": "xz -9 (best layout)", "strict": "strict (lossless)",
                     "statistical": "statistical, k = 2", "intensity": "intensity only"}[key]
            ax.plot(clocks, v / v[0], style, label=label)
        ax.plot(clocks, np.ones_like(clocks), ":", color="C3", label="seed §5.2: \"almost no more data\"")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log", base=2)
        ax.set_xticks(clocks, [f"{c:g}" for c in clocks])
        ax.set_xlabel("readout clock, kHz")
        h, w = rs[0]["size"]
        ax.set_title(f"static {h}×{w} scene, {rs[0]['duration_s'] * 1e3:g} ms, Q = {q:g} e⁻")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("coded size relative to 20 kHz (×)")
    axes[-1].legend(fontsize=8, loc="upper left")
    fig.suptitle("Cost of finer time precision: same light (mean intervals 0.1–1 ms), same duration, faster clock")
    fig.tight_layout()
    save_figure(path, fig)


# ---------------------------------------------------------------------------- printing

def print_rows(rows: list[dict]) -> None:
    for r in rows:
        g = r["generic"]
        print(f"\n{r['stream']}  {r['shape'][0]} ticks × {r['shape'][1]}×{r['shape'][2]}  {r['spikes']:,} spikes  "
              f"raw {r['raw_bytes'] / 1e6:.3g} MB ({r['raw_bits_per_spike']:.3g} bit/spike)"
              + (f"  entropy floor {r['entropy_floor_bits_per_spike']:.3g} bit/spike"
                 if "entropy_floor_bits_per_spike" in r else ""))
        print("  generic:  " + "  ".join(f"{k} {v['ratio_vs_raw']:.3g}×" for k, v in g.items())
              + f"  → best {r['best_generic']['name']} ({8 * r['best_generic']['bytes'] / r['spikes']:.3g} bit/spike)")
        print(f"  {'mode':18s} {'×raw':>7s} {'×best':>6s} {'bit/spike':>9s} {'enc Msp/s':>9s} {'dec Msp/s':>9s} "
              f"{'enc MB':>7s} {'dec MB':>7s} {'lossless':>8s} {'PSNR TFP':>9s} {'PSNR 1/ISI':>10s}")
        for label, m in r["modes"].items():
            ps = (f"{m['psnr_tfp_db']:8.3g}  {m['psnr_interval_db']:9.3g} " if "psnr_tfp_db" in m
                  else f"{'':9s} {'':10s}")
            print(f"  {label:18s} {m['ratio_vs_raw']:6.3g}× {m['ratio_vs_best_generic']:5.3g}× "
                  f"{m['bits_per_spike']:9.3g} "
                  f"{m['encode_mspikes_per_s']:9.3g} {m['decode_mspikes_per_s']:9.3g} {m['encode_peak_mb']:7.3g} "
                  f"{m['decode_peak_mb']:7.3g} {str(m['lossless']):>8s} {ps}")


def print_precision(rows: list[dict]) -> None:
    print("\ntime precision (seed 000 §5.2: finer time precision with almost no more data): size relative to 20 kHz")
    print(f"  {'Q e⁻':>6s} {'clock kHz':>9s} {'raw':>6s} {'xz best':>7s} {'strict':>7s} {'stat k=2':>8s} "
          f"{'intensity':>9s}   strict bytes")
    base = {}
    for r in rows:
        q = r["threshold_electrons"]
        if r["clock_hz"] == 20e3:
            base[q] = r
        b = base[q]
        print(f"  {q:6g} {r['clock_hz'] / 1e3:9g} {r['raw_bytes'] / b['raw_bytes']:5.3g}× "
              f"{r['best xz'] / b['best xz']:6.3g}× {r['strict'] / b['strict']:6.3g}× "
              f"{r['statistical'] / b['statistical']:7.3g}× {r['intensity'] / b['intensity']:8.3g}×   {r['strict']}")


# ---------------------------------------------------------------------------- corpus

#: The corpus is split ONCE, by name, into a tuning half and a held-out half: the shared files and the
#: scenes below are the tuning half (versions 4, 5 and 6 were tuned on them: version 4 on reds_sim, version 5
#: looking at all three shared files, version 6 on reds_sim2, real_uhsr, dilemma, hdr, night-road-fog and
#: step); every other built-in scene — those added later included — is held out. (The split was once "even
#: positions of the sorted scene list": adding a scene moved scenes between the halves.)
CORPUS_TUNING_SCENES = ("dilemma", "hdr", "night-road-fog", "step")
CORPUS_SCENE_SIZE = (64, 96)
CORPUS_TICKS = 320
CORPUS_Q = (100.0, 1e3, 1e4)
CORPUS_CLOCKS_HZ = (20e3, 40e3)


def corpus_streams():
    """(half, name, make) for every stream of the corpus; ``make()`` gives a SpikeStream."""
    from viform._validate import UnverifiedDataWarning
    from viform.light.catalog import BUILTIN_SCENES, builtin_scene
    from viform.sensors.spike_presets import _builtin
    from viform.stream.io import open_spikes

    def shared(f, hw):
        with warnings.catch_warnings():  # the shared files carry no viform checksums: read unverified, as expected
            warnings.simplefilter("ignore", UnverifiedDataWarning)
            return open_spikes(DATA / f, *hw).to_memory()

    out = []
    for fname, hw in (("reds_sim_400x250.dat", (250, 400)), ("reds_sim2_400x250.dat", (250, 400)),
                      ("real_uhsr_250x250.npz", (None, None))):
        if (DATA / fname).exists():
            out.append(("tuning", fname, lambda f=fname, hw=hw: shared(f, hw)))
        else:
            print(f"skip {fname}: not found under {DATA}", file=sys.stderr)
    h, w = CORPUS_SCENE_SIZE
    for scene in sorted(BUILTIN_SCENES):
        half = "tuning" if scene in CORPUS_TUNING_SCENES else "held-out"
        for q in CORPUS_Q:
            for clock in CORPUS_CLOCKS_HZ:
                def make(scene=scene, q=q, clock=clock):
                    # the SpikeOne preset's noise model (gain spread, dark current) at this Q and clock
                    sensor = _builtin("spikeone").sensor(threshold_electrons=q, clock_hz=clock, height=h, width=w)
                    return sensor.capture(builtin_scene(scene, h, w), CORPUS_TICKS / clock, seed=1)
                out.append((half, f"{scene} Q={q:g} {clock / 1e3:g} kHz", make))
    return out


def _cpu(fn):
    """(result, CPU-seconds of this process — every thread — spent in fn())."""
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def _code(stream: SpikeStream, path: Path, version: int, fast: bool = False) -> tuple[int, float, float]:
    """Strict ``version`` of ``stream``: bytes, encode and decode CPU-seconds; the decode is checked exact."""
    info, enc = _cpu(lambda: encode_source(stream, path, version=version, fast=fast))
    dec_spikes, dec = _cpu(lambda: np.concatenate([b for _, b in CodedFile(path).iter_blocks(1024)]))
    assert np.array_equal(dec_spikes, stream.spikes), f"version {version} is not lossless"
    return info["bytes"], enc, dec


def corpus_row(half: str, name: str, stream: SpikeStream, tmp: Path) -> dict:
    """Strict sizes and speeds (Mspikes per CPU-second) of the default version and of version 5, and of the
    best generic coder (xz -9, zstd -19 on both layouts), all in this process."""
    spikes = stream.spikes
    n_spikes = int(spikes.sum())
    raw = spikes.size / 8
    row = {"half": half, "stream": name, "shape": list(spikes.shape), "spikes": n_spikes, "raw_bytes": raw}
    for key, version, fast in (("v5", 5, False), ("new", VERSION, False), ("fast", VERSION, True)):
        nbytes, enc, dec = _code(stream, tmp / "c.vfc", version, fast)
        row[f"{key}_bytes"] = nbytes
        row[f"{key}_encode_mspikes_per_cpu_s"] = n_spikes / max(enc, 1e-9) / 1e6
        row[f"{key}_decode_mspikes_per_cpu_s"] = n_spikes / max(dec, 1e-9) / 1e6
    best = None
    for lay, data in layouts(spikes).items():
        for coder, fn in (("xz-9", lambda b: lzma.compress(b, preset=9)),
                          ("zstd-19", lambda b: zstandard.ZstdCompressor(level=19).compress(b))):
            packed, cpu = _cpu(lambda fn=fn, data=data: fn(data))
            row[f"{coder} {lay}_bytes"] = len(packed)
            row[f"{coder} {lay}_encode_mspikes_per_cpu_s"] = n_spikes / max(cpu, 1e-9) / 1e6
            if best is None or len(packed) < best[1]:
                best = (f"{coder} {lay}", len(packed))
    row.update(best_generic=best[0], best_generic_bytes=best[1], ratio_vs_raw=raw / row["new_bytes"],
               ratio_vs_best_generic=best[1] / row["new_bytes"], ratio_vs_v5=row["v5_bytes"] / row["new_bytes"],
               bits_per_spike=8 * row["new_bytes"] / max(1, n_spikes))
    return row


def print_corpus_header() -> None:
    v = VERSION
    print(f"{'half':<9}{'stream':<30}{'spikes':>10}{'×raw':>7}{'×generic':>9}{'v5 B':>10}{f'v{v} B':>10}"
          f"{'÷v5':>7}{'bit/sp':>7}   Mspikes per CPU-s: {'v5 enc':>7}{f'v{v} enc':>7}{'v5 dec':>7}"
          f"{f'v{v} dec':>7}{'zstd':>6}{'xz':>6}")


def print_corpus(rows: list[dict]) -> None:
    for r in rows:
        zs = r["zstd-19 time-major_encode_mspikes_per_cpu_s"]
        xz = r["xz-9 time-major_encode_mspikes_per_cpu_s"]
        print(f"{r['half']:<9}{r['stream'][:29]:<30}{r['spikes']:>10,}{r['ratio_vs_raw']:>7.3g}"
              f"{r['ratio_vs_best_generic']:>9.3g}{r['v5_bytes']:>10,}{r['new_bytes']:>10,}"
              f"{r['ratio_vs_v5']:>7.4f}{r['bits_per_spike']:>7.3f}   {'':19s}"
              f"{r['v5_encode_mspikes_per_cpu_s']:>7.3g}{r['new_encode_mspikes_per_cpu_s']:>7.3g}"
              f"{r['v5_decode_mspikes_per_cpu_s']:>7.3g}{r['new_decode_mspikes_per_cpu_s']:>7.3g}{zs:>6.3g}{xz:>6.3g}")


def print_corpus_summary(rows: list[dict]) -> None:
    v = VERSION
    for half in ("tuning", "held-out"):
        sel = [r for r in rows if r["half"] == half]
        if not sel:
            continue
        worse = [r["stream"] for r in sel if r["new_bytes"] > r["v5_bytes"]]
        print(f"{half}: {len(sel)} streams, version {v} larger than version 5 on {len(worse)} {worse or ''}; "
              f"size ratio v5 ÷ v{v} {min(r['ratio_vs_v5'] for r in sel):.4f}–{max(r['ratio_vs_v5'] for r in sel):.4f}"
              f" (mean {np.mean([r['ratio_vs_v5'] for r in sel]):.4f}); "
              f"≥ 1.5× the best generic coder: {sum(r['ratio_vs_best_generic'] >= 1.5 for r in sel)}/{len(sel)}")
    fast = [r["fast_bytes"] / r["new_bytes"] for r in rows]
    print(f"--fast (version 5, interval model only) ÷ version {v} size: {min(fast):.4f}–{max(fast):.4f} "
          f"(mean {np.mean(fast):.4f})")
    files = [r for r in rows if r["stream"].endswith((".dat", ".npz"))]
    if files:  # the goal's streams: the shared REDS clips and the real recording, over all their spikes
        tot = sum(r["spikes"] for r in files)
        for key, what in (("v5", "version 5"), ("new", f"version {v}"), ("fast", "--fast (version 5, one model)")):
            enc = sum(r["spikes"] / r[f"{key}_encode_mspikes_per_cpu_s"] for r in files)
            dec = sum(r["spikes"] / r[f"{key}_decode_mspikes_per_cpu_s"] for r in files)
            print(f"shared files ({len(files)}), {what}: encode {tot / enc:.3g}, decode {tot / dec:.3g} Mspikes per "
                  f"CPU-s (goal for the default: encode ≥ 10, decode ≥ 20)")


def run_corpus(args) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        warm = static_scene(100.0, (24, 24), 200)[0]
        for version, fast in ((5, False), (VERSION, False), (VERSION, True)):  # compile or load before timing
            encode_source(warm, tmp / "warm.vfc", version=version, fast=fast)
            CodedFile(tmp / "warm.vfc").verify()
        print_corpus_header()
        for half, name, make in corpus_streams():
            if args.only and args.only not in name:
                continue
            rows.append(corpus_row(half, name, make(), tmp))
            print_corpus(rows[-1:])
            sys.stdout.flush()
    print()
    print_corpus_summary(rows)
    print(f"load after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    if args.json:
        from viform._io import write_json

        write_json(args.json, {"corpus": rows})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller simulated scenes")
    ap.add_argument("--json", type=Path, default=None, help="also write the results as JSON here")
    ap.add_argument("--figure", type=Path, default=None, help="draw the time-precision figure (PNG) here")
    ap.add_argument("--only", default=None, help="run only streams whose name contains this")
    ap.add_argument("--no-precision", action="store_true", help="skip the time-precision row")
    ap.add_argument("--corpus", action="store_true",
                    help="the evaluation corpus (shared files, every built-in scene at Q = 100, 1e3, 1e4 e- and "
                         "20/40 kHz), split into a tuning and a held-out half: the default version against version 5, "
                         "xz and zstd per stream, sizes and Mspikes per CPU-second")
    args = ap.parse_args(argv)
    if args.corpus:
        print(f"load: {os.getloadavg()[0]:.1f} {os.getloadavg()[1]:.1f} {os.getloadavg()[2]:.1f} on "
              f"{os.cpu_count()} CPUs; coding threads: {coding_threads()}")
        run_corpus(args)
        return
    from viform.stream.io import open_spikes

    print(f"load: {os.getloadavg()[0]:.1f} {os.getloadavg()[1]:.1f} {os.getloadavg()[2]:.1f} on {os.cpu_count()} CPUs "
          f"(speeds are shared-machine figures); coding threads: {coding_threads()} (VIFORM_THREADS); "
          f"'strict' is format version {VERSION}, 'strict version 5' the previous format")
    rows = []
    size = (48, 48) if args.quick else (96, 96)
    ticks = 2000 if args.quick else 4000
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        streams = []
        for fname, hw in (("reds_sim_400x250.dat", (250, 400)), ("real_uhsr_250x250.npz", (None, None))):
            if (DATA / fname).exists():
                streams.append((fname, lambda f=fname, hw=hw: (open_spikes(DATA / f, *hw).to_memory(), None)))
            else:
                print(f"skip {fname}: not found under {DATA}", file=sys.stderr)
        for q in (100.0, 1000.0, 1e4):
            streams.append((f"sim static Q={q:g}", lambda q=q: static_scene(q, size, ticks)))
        streams.append(("sim static Q=1e4 noisy", lambda: static_scene(1e4, size, ticks, noise=True)))
        for q in (100.0, 1e4):
            streams.append((f"sim moving 400 px/s Q={q:g}", lambda q=q: (moving_scene(q, size, ticks), None)))
        warm = static_scene(100.0, (24, 24), 200)[0]
        for version in (5, VERSION):  # compile (or load) the coders before any timing
            encode_source(warm, tmp / "warm.vfc", version=version)
            CodedFile(tmp / "warm.vfc").verify()
        for name, make in streams:
            if args.only and args.only not in name:
                continue
            s, mean_iv = make()
            floor = None
            if mean_iv is not None:
                floor = entropy_floor_bits_per_spike(mean_iv, s.threshold_electrons)
            rows.append(bench_stream(name, s, tmp, floor=floor))
            print_rows(rows[-1:])
            sys.stdout.flush()
        prec = [] if args.no_precision else time_precision(args.quick, tmp)
    if prec:
        print_precision(prec)
        if args.figure:
            figure(prec, args.figure)
            print(f"figure: {args.figure}")
    print("\nstrict / best generic per stream: " + ", ".join(
        f"{r['stream']} {r['modes']['strict']['ratio_vs_best_generic']:.3g}×" for r in rows))
    if args.json:
        from viform._io import write_json

        write_json(args.json, {"streams": rows, "time_precision": prec})


if __name__ == "__main__":
    main()
