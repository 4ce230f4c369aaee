"""Throughput of the seed-002 histogram counter and shift equalization on 1280 × 720 frames.

Reference: a plain np.bincount histogram and a floating-point LUT (eq. (3)), same process.
Run: python benchmarks/bench_highspeed_histogram.py
"""

import time

import numpy as np

from viform.isp.histogram import equalization_lut_float, equalization_lut_shift, equalize, histogram_counter


def _time(fn, repeat=20):
    fn()
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat


def main():
    rng = np.random.default_rng(0)
    frame = np.clip(rng.normal(60, 20, (720, 1280)), 0, 255).astype(np.uint8)
    mpix = frame.size / 1e6
    t_counter = _time(lambda: histogram_counter(frame))
    t_ref = _time(lambda: np.bincount(frame.ravel(), minlength=256))
    hist = histogram_counter(frame)
    t_shift = _time(lambda: equalize(frame, equalization_lut_shift(hist)))
    t_float = _time(lambda: equalize(frame, np.rint(equalization_lut_float(hist))))
    print(f"histogram, 8-bank counter : {mpix / t_counter:8.1f} Mpixel/s ({1 / t_counter:7.0f} frames/s)")
    print(f"histogram, np.bincount    : {mpix / t_ref:8.1f} Mpixel/s; counter/reference = {t_ref / t_counter:.2f}")
    print(f"equalize, shift LUT       : {mpix / t_shift:8.1f} Mpixel/s ({1 / t_shift:7.0f} frames/s)")
    print(f"equalize, float LUT       : {mpix / t_float:8.1f} Mpixel/s; shift/float = {t_float / t_shift:.2f}")
    print("the camera needs 1.54 Gpixel/s (1280 x 720 x 1666.7 fps) for every frame, "
          "or 0.51 Gpixel/s for the 3:1 transmitted stream")


if __name__ == "__main__":
    main()
