"""Figures for sensor characterization: response curves, SNR vs irradiance, photon transfer.

* :func:`response_figure` — normalized output vs illuminance of several sensors on one
  figure, linear and log axes side by side (normal, segmented, overflow, spike …);
* :func:`snr_figure` — SNR (dB) vs illuminance;
* :func:`ptc_figure` — the photon-transfer curve of an EMVA 1288 sweep (temporal
  variance vs mean, both dark-corrected) with the fitted system gain K.

Each function returns a matplotlib Figure (Agg backend); save it with
:func:`viform._io.save_figure`.
"""

from __future__ import annotations

import numpy as np

from viform.measure.emva1288 import measure_response


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def frame_response_curve(sensor, lux_values, *, size: int = 16, seed: int = 0) -> dict:
    """Normalized mean output (fraction of the largest signal) and SNR of a frame sensor."""
    resp = measure_response(sensor, lux_values, height=size, width=size, seed=seed)
    sig = resp["signal_dn"]
    return {"lux": resp["lux"], "output": sig / max(float(sig.max()), 1e-12), "snr": resp["snr"], "raw": resp}


def spike_response_curve(sensor, lux_values, *, pixels: int = 32, seed: int = 0) -> dict:
    """Spike rate per tick (1 = one spike every tick, the ceiling) and interval SNR."""
    from viform.measure.spike_characterization import interval_snr_curve

    c = interval_snr_curve(sensor, lux_values, pixels=pixels, seed=seed, duration_s=2000 / sensor.parameters.clock_hz)
    return {"lux": c["lux"], "output": c["rate_per_tick"], "snr": c["snr"], "raw": c}


def response_figure(curves: dict, title: str = "Response curves"):
    """Output vs illuminance for each named curve: linear axes (left), log axes (right)."""
    plt = _plt()
    fig, (ax_lin, ax_log) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, c in curves.items():
        ax_lin.plot(c["lux"], c["output"], label=name)
        ax_log.loglog(c["lux"], np.maximum(c["output"], 1e-6), label=name)
    # Linear panel: up to a little past the last sensor's saturation, so the knees show.
    onsets = [float(np.asarray(c["lux"])[np.argmax(np.asarray(c["output"]) >= 0.999)]) for c in curves.values()]
    ax_lin.set_xlim(0, 1.3 * max(onsets))
    ax_lin.set(xlabel="illuminance on the sensor (lux)", ylabel="output / max output", title="linear axes")
    ax_log.set(xlabel="illuminance on the sensor (lux)", ylabel="output / max output", title="log axes")
    for ax in (ax_lin, ax_log):
        ax.grid(True, which="both", alpha=0.3)
    ax_log.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def snr_figure(curves: dict, title: str = "SNR vs irradiance"):
    """SNR in dB vs illuminance (input-referred for frame sensors, interval SNR for spikes)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for name, c in curves.items():
        snr = np.asarray(c["snr"], dtype=np.float64)
        ok = np.isfinite(snr) & (snr > 0)
        ax.semilogx(np.asarray(c["lux"])[ok], 20 * np.log10(snr[ok]), label=name)
    ax.axhline(0.0, color="k", lw=0.8, ls=":")
    ax.set(xlabel="illuminance on the sensor (lux)", ylabel="SNR (dB)", title=title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def ptc_figure(result: dict, title: str = "Photon transfer curve (EMVA 1288)"):
    """σ²_y − σ²_y.dark vs μ_y − μ_y.dark (log–log) with the line of slope K."""
    plt = _plt()
    c = result["curves"]
    x = c["mu_y"] - c["mu_y_dark"]
    y = c["sigma2_y"] - c["sigma2_y_dark"]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ok = (x > 0) & (y > 0)
    ax.loglog(x[ok], y[ok], "o", ms=3, label="measured")
    k = result["system_gain_dn_per_e"]
    xs = np.geomspace(max(x[ok].min(), 1e-3), x[ok].max(), 50)
    ax.loglog(xs, k * xs, "-", label=f"K = {k:.4g} DN/e⁻")
    i = result["saturation_index"]
    ax.axvline(x[i], color="r", ls=":", label="saturation (max variance)")
    ax.set(xlabel="μ_y − μ_y.dark (DN)", ylabel="σ²_y − σ²_y.dark (DN²)", title=title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
