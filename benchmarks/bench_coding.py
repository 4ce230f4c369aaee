"""Compression of first-spike coding (seed 000 §5.2) against general-purpose coders.

For each stream: size of the ``.vfc`` file in strict mode (lossless) and statistical mode,
as a ratio to the packed raw bits (1 bit per pixel per tick), next to zlib -9, xz -9e and
zstd -19 run on the same packed bits in this process; encode and decode throughput
(Mspikes/s and raw MB/s); for the lossy modes the PSNR of interval imaging (Q/τ at an
instant, seed 000 §3.3.2) of the decoded stream against the uncoded stream, and for the
simulated scenes the PSNR of both against the true light (the loss in dB).

Run:  python benchmarks/bench_coding.py [--quick] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import lzma
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np
import zstandard

from viform.coding.aer_file import CodedFile, encode_source
from viform.stream.container import SpikeStream

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "spike"


def interval_rate(spikes: np.ndarray, ticks) -> np.ndarray:
    """1/τ (spikes per tick) of the interval holding each tick, (len(ticks), H, W); NaN where cut by an end."""
    try:
        from viform.imaging.interval import interval_ticks

        tau, censored = interval_ticks(SpikeStream(spikes, 1.0), ticks)
        rate = 1.0 / tau.astype(float)
        rate[censored] = np.nan
        return rate
    except ImportError:  # the imaging module is not there yet: plain helper
        t, h, w = spikes.shape
        flat = spikes.reshape(t, -1)
        out = np.full((len(ticks), h * w), np.nan)
        idx = np.arange(t)[:, None]
        last = np.maximum.accumulate(np.where(flat, idx, -1), axis=0)
        nxt = np.minimum.accumulate(np.where(flat, idx, t)[::-1], axis=0)[::-1]
        for m, k in enumerate(ticks):
            a, b = last[k], nxt[k + 1] if k + 1 < t else np.full(h * w, t)
            ok = (a >= 0) & (b < t)
            out[m, ok] = 1.0 / (b[ok] - a[ok])
        return out.reshape(len(ticks), h, w)


def psnr(x, y, peak) -> float:
    ok = np.isfinite(x) & np.isfinite(y)
    mse = np.mean((x[ok] - y[ok]) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(peak**2 / mse)


def general_coders(packed: bytes) -> dict:
    out = {}
    for name, fn in (("zlib-9", lambda b: zlib.compress(b, 9)),
                     ("xz-9e", lambda b: lzma.compress(b, preset=9 | lzma.PRESET_EXTREME)),
                     ("zstd-19", lambda b: zstandard.ZstdCompressor(level=19).compress(b))):
        t0 = time.perf_counter()
        n = len(fn(packed))
        out[name] = {"bytes": n, "ratio": len(packed) / n, "seconds": time.perf_counter() - t0}
    return out


def bench_stream(name: str, stream: SpikeStream, truth_rate=None, q=None, tmp=Path(".")) -> dict:
    spikes = stream.spikes
    t, h, w = spikes.shape
    packed = np.packbits(spikes.reshape(t, -1), axis=1, bitorder="little").tobytes()
    n_spikes = int(spikes.sum())
    row = {"stream": name, "shape": [t, h, w], "spikes": n_spikes, "raw_bytes": len(packed),
           "general": general_coders(packed)}
    probe = np.linspace(t * 0.2, t * 0.8, 5).astype(int)
    rate_raw = interval_rate(spikes, probe)
    for mode in ("strict", "statistical", "intensity"):
        if mode == "statistical" and q is None:
            continue
        path = tmp / f"{name}-{mode}.vfc"
        t0 = time.perf_counter()
        info = encode_source(stream, path, mode, k=2.0, threshold_electrons=q, slack_ticks=1)
        enc_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        cf = CodedFile(path)
        dec = np.concatenate([b for _, b in cf.iter_blocks(1024)])
        dec_s = time.perf_counter() - t0
        r = {"bytes": info["bytes"], "ratio_vs_raw": len(packed) / info["bytes"],
             "ratio_vs_xz": row["general"]["xz-9e"]["bytes"] / info["bytes"],
             "bits_per_spike": 8 * info["bytes"] / max(1, n_spikes),
             "encode_mspikes_per_s": n_spikes / enc_s / 1e6, "encode_raw_mb_per_s": len(packed) / enc_s / 1e6,
             "decode_mspikes_per_s": n_spikes / dec_s / 1e6, "decode_raw_mb_per_s": len(packed) / dec_s / 1e6,
             "lossless": bool(np.array_equal(dec, spikes))}
        if mode != "strict":
            rate_dec = interval_rate(dec, probe)
            peak = np.nanmax(rate_raw)
            r["psnr_vs_uncoded_db"] = psnr(rate_dec, rate_raw, peak)
            if truth_rate is not None:
                tr = np.broadcast_to(truth_rate, rate_raw.shape)
                r["psnr_uncoded_vs_truth_db"] = psnr(rate_raw, tr, tr.max())
                r["psnr_decoded_vs_truth_db"] = psnr(rate_dec, tr, tr.max())
                r["loss_db"] = r["psnr_uncoded_vs_truth_db"] - r["psnr_decoded_vs_truth_db"]
        row[mode] = r
    return row


def simulated(kind: str, size=(120, 160), ticks=4000, q=400.0):
    from viform.light.scenes import StillScene, TranslatingScene
    from viform.sensors.spike import SpikeSensor

    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=20.0)
    h, w = size
    # brightness chosen so intervals span about 4–60 ticks (a typical indoor range at 40 kHz)
    e_tick = np.random.default_rng(0).uniform(q / 60, q / 4, (h, w))
    e_tick = np.round(e_tick / 10, 0) * 10 + q / 60
    base_lux = sensor.parameters.optics.lux_from_electrons_per_s(e_tick * sensor.parameters.clock_hz)
    if kind == "static":
        scene = StillScene(base_lux)
        truth = (e_tick + 20.0 / 40e3) / q
    else:
        v = 20.0 if kind == "slow" else 2000.0  # px/s
        scene = TranslatingScene(h, w, velocity_px_per_s=(v, 0.0))
        truth = None
    s = sensor.capture(scene, ticks / sensor.parameters.clock_hz, seed=1)
    return s, truth


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller simulated scenes")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    from viform.stream.io import open_spikes

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for fname, hw in (("reds_sim_400x250.dat", (250, 400)), ("real_uhsr_250x250.npz", (None, None))):
            if (DATA / fname).exists():
                s = open_spikes(DATA / fname, *hw).to_memory()
                rows.append(bench_stream(fname, s, tmp=tmp))
            else:
                print(f"skip {fname}: not found under {DATA}", file=sys.stderr)
        ticks = 1500 if args.quick else 4000
        for kind in ("static", "slow", "fast"):
            s, truth = simulated(kind, ticks=ticks)
            rows.append(bench_stream(f"sim-{kind}", s, truth, q=s.threshold_electrons, tmp=tmp))
    for r in rows:
        g = r["general"]
        print(f"\n{r['stream']}  {r['shape']}  {r['spikes']} spikes  raw {r['raw_bytes']} B  "
              f"zlib {g['zlib-9']['ratio']:.2f}×  xz {g['xz-9e']['ratio']:.2f}×  zstd {g['zstd-19']['ratio']:.2f}×")
        for mode in ("strict", "statistical", "intensity"):
            if mode not in r:
                continue
            m = r[mode]
            extra = ""
            if "psnr_vs_uncoded_db" in m:
                extra = f"  PSNR vs uncoded {m['psnr_vs_uncoded_db']:.1f} dB"
            if "loss_db" in m:
                extra += (f"  vs truth {m['psnr_uncoded_vs_truth_db']:.2f} → {m['psnr_decoded_vs_truth_db']:.2f} dB"
                          f" (loss {m['loss_db']:.2f} dB)")
            print(f"  {mode:11s} {m['ratio_vs_raw']:6.2f}× raw  {m['ratio_vs_xz']:5.2f}× xz  "
                  f"{m['bits_per_spike']:.2f} bit/spike  enc {m['encode_mspikes_per_s']:.1f} Msp/s "
                  f"({m['encode_raw_mb_per_s']:.1f} MB/s)  dec {m['decode_mspikes_per_s']:.1f} Msp/s "
                  f"({m['decode_raw_mb_per_s']:.1f} MB/s)  lossless={m['lossless']}{extra}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
