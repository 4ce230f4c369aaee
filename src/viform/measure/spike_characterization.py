"""Spike-camera counterpart of the EMVA 1288 figures (seed 000 §4.2–4.4).

A spike pixel measures light by the time τ it takes to collect the threshold Q, so its
dynamic range is set by intervals, not by charge (seed 000 §4.4)::

    DR = 20·lg(τ̂ / τ̌) = 20·lg(Q / (τ̌ · I_d))  dB

* τ̌, the shortest usable interval, is the readout period 1/clock (one spike per tick at
  most, seed 000 §4.3): light above Q·clock e⁻/s is not distinguished.
* τ̂, the longest signal interval, is Q/I_d: a pixel in the dark still fires every Q/I_d
  seconds, so longer intervals are indistinguishable from dark current (seed 000 §4.4).

:func:`measure_interval_dynamic_range` measures both from simulated flat fields (the mean
inter-spike interval in saturating light and in the dark) and compares them with the
parameters. SNR from the interval statistics: a single interval τ estimates the light as
Q/τ; with exact photon statistics τ is Gamma(Q)-distributed in collected-charge time, so
the single-interval SNR mean(τ)/std(τ) tends to √Q at low light, and drops as ticks
quantize τ near τ̌ (:func:`interval_snr_curve`).
"""

from __future__ import annotations

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.light.scenes import StillScene


def _require_spike():
    try:
        from viform.sensors.spike import SpikeSensor
    except ImportError:  # pragma: no cover - the module ships with viform
        raise ViformError("the spike sensor module viform.sensors.spike is not available") from None
    return SpikeSensor


def intervals_ticks(spikes: np.ndarray) -> list[np.ndarray]:
    """Inter-spike intervals (ticks) of each pixel of a (T, H, W) bool array; the first
    spike's interval is dropped (its start is unknown)."""
    t, h, w = spikes.shape
    flat = spikes.reshape(t, h * w)
    out = []
    for p in range(h * w):
        times = np.flatnonzero(flat[:, p])
        if times.size >= 2:
            out.append(np.diff(times))
    return out


def expected_interval_dynamic_range(parameters) -> dict:
    """τ̌, τ̂ and DR implied by the spike sensor's parameters (seed 000 §4.4)."""
    tau_min = parameters.shortest_interval_s
    tau_max = parameters.longest_signal_interval_s
    if not np.isfinite(tau_max):
        raise ViformError("dark_current_e_per_s = 0: τ̂ = Q/I_d is infinite and so is the dynamic range")
    return {
        "shortest_interval_s": tau_min,
        "longest_interval_s": tau_max,
        "dynamic_range": tau_max / tau_min,
        "dynamic_range_db": 20 * np.log10(tau_max / tau_min),
    }


def measure_interval_dynamic_range(
    sensor, *, height: int = 32, width: int = 32, dark_duration_s=None, bright_lux=None, seed: int = 0
) -> dict:
    """Measure τ̌ (mean interval in saturating light) and τ̂ (mean interval in the dark).

    τ̂ is measured as pixels × duration / dark spikes (the dark spike rate), which uses
    every dark spike even when most pixels fire only a few times. ``dark_duration_s``
    defaults to 4·τ̂ expected (at least 4 dark spikes per pixel on average).
    """
    p = sensor.parameters
    expected = expected_interval_dynamic_range(p)
    height, width = check_int("height", height, 1), check_int("width", width, 1)
    if dark_duration_s is None:
        dark_duration_s = 4 * expected["longest_interval_s"]
    dark_duration_s = check_positive("dark_duration_s", dark_duration_s)
    # streamed and counted block by block: at chip thresholds (Q ~ 1e4 e-) τ̂ is minutes, far
    # more ticks than memory holds as bits
    dark = sensor.stream(StillScene(np.zeros((height, width))), dark_duration_s, seed=seed, reuse_buffer=True)
    block_ticks = max(1, (64 << 20) // (height * width))
    n_dark = sum(int(np.count_nonzero(block)) for _, block in dark.iter_blocks(block_ticks))
    if n_dark == 0:
        raise ViformError("no dark spikes in the simulated span; lengthen dark_duration_s")
    tau_hat = height * width * dark.n_ticks / dark.clock_hz / n_dark
    if bright_lux is None:  # 10× the light that fills Q in one tick
        bright_lux = 10 * p.threshold_electrons * p.clock_hz / p.optics.electrons_per_lux_second
    bright = sensor.capture(StillScene(np.full((height, width), float(bright_lux))), 200 / p.clock_hz, seed=seed + 1)
    iv = np.concatenate(intervals_ticks(bright.spikes))
    tau_check = float(iv.mean()) / p.clock_hz
    dr = tau_hat / tau_check
    return {
        "shortest_interval_s": tau_check,
        "longest_interval_s": float(tau_hat),
        "dynamic_range": float(dr),
        "dynamic_range_db": float(20 * np.log10(dr)),
        "dark_spikes": n_dark,
        "expected": expected,
    }


def interval_snr_curve(sensor, lux_values, *, pixels: int = 64, duration_s: float | None = None, seed: int = 0) -> dict:
    """Single-interval SNR = mean(τ)/std(τ) and spike rate per tick vs illuminance.

    All illuminances are shot at once: a (len(lux), pixels) still scene, one row per level.
    Returns ``lux``, ``rate_per_tick`` (mean spikes per tick), ``mean_interval_s``,
    ``snr`` (NaN where fewer than 10 intervals or saturated), ``snr_db``.
    """
    lux = np.asarray(lux_values, dtype=np.float64)
    if lux.ndim != 1 or lux.size < 1:
        raise ViformError("lux_values must be a 1-D list of illuminances")
    p = sensor.parameters
    if duration_s is None:  # enough for ~20 intervals at the dimmest level, capped at 0.5 s
        rate = (p.optics.electrons_per_s(lux.min()) + p.dark_current_e_per_s) / p.threshold_electrons
        duration_s = float(np.clip(20 / max(rate, 1e-9), 400 / p.clock_hz, 0.5))
    scene = StillScene(np.repeat(lux[:, None], check_int("pixels", pixels, 1), axis=1))
    stream = sensor.capture(scene, duration_s, seed=seed)
    spikes = stream.spikes
    rate = spikes.mean(axis=(0, 2))
    snr, mean_iv = np.full(lux.size, np.nan), np.full(lux.size, np.nan)
    for i in range(lux.size):
        iv = intervals_ticks(spikes[:, i : i + 1, :])
        iv = np.concatenate(iv) if iv else np.array([])
        if iv.size >= 10 and rate[i] < 0.99:  # saturated pixels fire every tick: no estimate
            mean_iv[i] = iv.mean() / p.clock_hz
            sd = iv.std(ddof=1)
            snr[i] = iv.mean() / sd if sd > 0 else np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        snr_db = 20 * np.log10(snr)
    return {
        "lux": lux,
        "rate_per_tick": rate,
        "mean_interval_s": mean_iv,
        "snr": snr,
        "snr_db": snr_db,
        "duration_s": duration_s,
    }


def characterize_spike_sensor(
    sensor, *, height: int = 16, width: int = 16, seed: int = 0, lux_values=None, dark_duration_s=None
) -> dict:
    """Interval DR (measured and expected) and the interval-SNR curve of a spike sensor.

    Parameters
    ----------
    sensor : SpikeSensor
        The sensor.
    height, width : int
        Size of the flat fields, pixels.
    seed : int
        Seed of the sensor's noise.
    lux_values : sequence of float, optional
        Illuminances of the SNR curve, lux (default: 12, logarithmically over the sensor's range).
    dark_duration_s : float, optional
        Length of the dark capture, s (default: about 4 expected dark intervals).

    Returns
    -------
    dict
        Measured and expected interval dynamic range (dB), the interval-SNR curve
        (``snr_curve``) and the expected low-light SNR (``snr_low_light_expected_db``).
    """
    _require_spike()
    p = sensor.parameters
    dr = measure_interval_dynamic_range(sensor, height=height, width=width, seed=seed, dark_duration_s=dark_duration_s)
    if lux_values is None:
        lo = p.dark_current_e_per_s / p.optics.electrons_per_lux_second
        hi = 30 * p.threshold_electrons * p.clock_hz / p.optics.electrons_per_lux_second
        lux_values = np.geomspace(max(lo, 1e-6) * 10, hi, 12)
    curve = interval_snr_curve(sensor, lux_values, seed=seed + 7)
    return {
        "method": "spike intervals (seed 000 §4.2–4.4)",
        **dr,
        "snr_curve": curve,
        "snr_low_light_expected_db": float(10 * np.log10(p.threshold_electrons)),
    }
