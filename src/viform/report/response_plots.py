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


def meaningful(c: dict, sat_fraction: float = 0.995) -> np.ndarray:
    """Points of a curve where the quantity means something: SNR ≥ 1 (above the noise floor)
    and not past saturation (the output has reached ``sat_fraction`` of its plateau; the first
    saturated point is kept so the curve ends at the knee into the plateau)."""
    snr = np.asarray(c.get("snr", np.ones(len(c["lux"]))), dtype=np.float64)
    out = np.asarray(c["output"], dtype=np.float64)
    ok = np.isfinite(snr) & (snr >= 1.0)
    sat = np.nonzero(out >= sat_fraction * np.nanmax(out))[0]
    if sat.size:
        ok[sat[0] + 1:] = False
    return ok


def response_figure(curves: dict, title: str = "Response curves", highlight: str | None = None):
    """Output vs illuminance for each named curve: linear axes (left), log axes (right).

    Each curve starts where its SNR reaches 1 (below, the output is noise); the plateau past
    saturation is drawn flat on the linear axes only. ``highlight`` names the curve drawn
    bold (the sensor being characterized)."""
    plt = _plt()
    fig, (ax_lin, ax_log) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, c in curves.items():
        lux, out = np.asarray(c["lux"]), np.asarray(c["output"])
        snr = np.asarray(c.get("snr", np.ones(len(lux))), dtype=np.float64)
        ok = np.isfinite(snr) & (snr >= 1.0)
        lw, z = (2.6, 3) if name == highlight else (1.2, 2)
        ax_lin.plot(lux[ok], out[ok], label=name, lw=lw, zorder=z)
        ax_log.loglog(lux[ok], out[ok], label=name, lw=lw, zorder=z)
    # Linear panel: up to a little past the last sensor's saturation, so the knees show.
    onsets = [float(np.asarray(c["lux"])[np.argmax(np.asarray(c["output"]) >= 0.999)]) for c in curves.values()]
    ax_lin.set_xlim(0, 1.3 * max(onsets))
    ax_lin.set(xlabel="illuminance on the sensor (lux)", ylabel="output / max output", title="linear axes")
    ax_log.set(xlabel="illuminance on the sensor (lux)", ylabel="output / max output",
               title="log axes (from SNR = 1)")
    for ax in (ax_lin, ax_log):
        ax.grid(True, which="both", alpha=0.3)
    ax_log.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def snr_figure(curves: dict, title: str = "SNR vs irradiance"):
    """SNR in dB vs illuminance (input-referred for frame sensors, interval SNR for spikes).

    Curves stop where SNR means nothing: below SNR = 1 (0 dB) and past saturation (see
    :func:`meaningful`); saturation is marked with a cross."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for j, (name, c) in enumerate(curves.items()):
        snr = np.asarray(c["snr"], dtype=np.float64)
        lux = np.asarray(c["lux"])
        ok = meaningful(c) if "output" in c else (np.isfinite(snr) & (snr >= 1.0))
        ax.semilogx(lux[ok], 20 * np.log10(snr[ok]), label=name, color=f"C{j}")
        if "output" in c and ok.any():
            last = np.nonzero(ok)[0][-1]
            if np.asarray(c["output"])[last] >= 0.995 * np.nanmax(c["output"]):
                ax.plot(lux[last], 20 * np.log10(snr[last]), "x", color=f"C{j}", ms=8)
    ax.plot([], [], "kx", label="saturation (curve ends)")
    ax.axhline(0.0, color="k", lw=0.8, ls=":")
    ax.set_ylim(bottom=0.0)
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
