"""Figures for sensor characterization: response curves, SNR vs irradiance, photon transfer.

* :func:`response_figure` — normalized output vs illuminance of several sensors on one
  figure, linear and log axes side by side (normal, segmented, overflow, spike …);
* :func:`snr_figure` — SNR (dB) vs illuminance (ends before saturation);
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
    and before saturation (the output has reached ``sat_fraction`` of its plateau). The first
    saturated point is dropped too: clipping collapses its variance, so its SNR would jump
    up (39 → 61 dB on cmos) at the very end of the curve."""
    snr = np.asarray(c.get("snr", np.ones(len(c["lux"]))), dtype=np.float64)
    out = np.asarray(c["output"], dtype=np.float64)
    ok = np.isfinite(snr) & (snr >= 1.0)
    if saturates(c, sat_fraction):
        ok[np.nonzero(out >= sat_fraction * np.nanmax(out))[0][0]:] = False
    return ok


def saturates(c: dict, sat_fraction: float = 0.995) -> bool:
    """Whether the curve reaches its plateau within its range (the output stops rising)."""
    out = np.asarray(c["output"], dtype=np.float64)
    first = np.nonzero(out >= sat_fraction * np.nanmax(out))[0][0]
    return bool(first < out.size - 1)


#: Line styles and markers that keep overlapping curves apart (each legend entry visible).
_STYLES = (("-", None), ("--", "o"), (":", "s"), ("-.", "^"), ((0, (5, 1, 1, 1)), "v"), ((0, (1, 1)), "D"))


def response_figure(curves: dict, title: str = "Response curves", highlight: str | None = None,
                    knees_lux: dict | None = None):
    """Output vs illuminance for each named curve: linear axes (left), log axes (right).

    Each curve starts where its SNR reaches 1 (below, the output is noise). Curves that
    coincide stay visible: each has its own dash pattern and hollow markers, drawn over the
    bold ``highlight`` (the sensor being characterized), which sits underneath. The linear
    panel spans a little past the highlighted sensor's saturation (else the slowest one's),
    so its response is a curve rather than a line on the y axis; both panels have a legend.

    ``knees_lux`` (name → illuminance, lux), for a compressive pixel such as seed 003's
    conditional overflow: a third panel draws the bold sensor's output on a linear axis
    against log illuminance with its knees marked. On log–log axes a segment of small slope
    riding on a large output (seed 003 fig. 6, B→D: slope ≈ 1/300 of A→B) looks flat,
    although the output still rises and its SNR stays above 30 dB."""
    plt = _plt()
    if knees_lux and highlight in curves:
        fig, (ax_lin, ax_log, ax_knee) = plt.subplots(1, 3, figsize=(17, 4.8))
    else:
        fig, (ax_lin, ax_log) = plt.subplots(1, 2, figsize=(12, 4.6))
        ax_knee = None
    for j, (name, c) in enumerate(curves.items()):
        lux, out = np.asarray(c["lux"]), np.asarray(c["output"])
        snr = np.asarray(c.get("snr", np.ones(len(lux))), dtype=np.float64)
        ok = np.isfinite(snr) & (snr >= 1.0)
        ls, mk = _STYLES[j % len(_STYLES)]
        if name == highlight:
            kw = dict(lw=4.0, ls="-", marker=None, zorder=2, alpha=0.45, color="k")
        else:
            kw = dict(lw=1.3, ls=ls, marker=mk, markevery=0.08, ms=5, mfc="none", zorder=3 + j, color=f"C{j}")
        ax_lin.plot(lux[ok], out[ok], label=name, **kw)
        ax_log.loglog(lux[ok], out[ok], label=name, **kw)
    onsets = {name: float(np.asarray(c["lux"])[np.argmax(np.asarray(c["output"]) >= 0.999)])
              for name, c in curves.items()}
    ax_lin.set_xlim(0, 1.5 * onsets.get(highlight, max(onsets.values())))
    ax_lin.set_ylim(0, 1.05)
    ax_lin.set(xlabel="illuminance on the sensor (lux)", ylabel="output / max output",
               title="linear axes, up to the bold sensor's saturation")
    ax_log.set(xlabel="illuminance on the sensor (lux)", ylabel="output / max output",
               title="log axes (from SNR = 1)")
    for ax in (ax_lin, ax_log):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    if ax_knee is not None:
        _knee_panel(ax_knee, curves[highlight], knees_lux)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _knee_panel(ax, c: dict, knees_lux: dict) -> None:
    """The bold sensor's output (linear) against log illuminance, its knees marked, and the
    slope of each segment relative to the first (what the log–log panel hides)."""
    lux, out = np.asarray(c["lux"], dtype=np.float64), np.asarray(c["output"], dtype=np.float64)
    ok = meaningful(c)
    last = np.nonzero(out >= 0.999 * np.nanmax(out))[0][0]  # the plateau's first point
    ok[last] = True
    ax.semilogx(lux[ok], out[ok], "k-", lw=2.5, alpha=0.6)
    names = sorted(knees_lux, key=knees_lux.get)
    edges = [float(lux[ok][0]), *(float(knees_lux[n]) for n in names)]
    slopes = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        ya, yb = np.interp([a, b], lux, out)
        slopes.append((yb - ya) / (b - a) if b > a else np.nan)
    for n in names:
        x = knees_lux[n]
        ax.axvline(x, color="C3", ls=":", lw=1)
        ax.text(x, 1.13, n.split()[0], color="C3", fontsize=9, ha="center", va="center", weight="bold",
                bbox=dict(fc="white", ec="none", pad=1))
    for a, b, sl in zip(edges[:-1], edges[1:], slopes, strict=True):
        if np.isfinite(sl) and slopes[0] > 0 and b > 4 * a:  # room for the note
            rel = sl / slopes[0]
            text = "×1" if abs(rel - 1) < 1e-9 else f"×1/{1 / rel:.0f}" if rel < 1 else f"×{rel:.2g}"
            # one row of notes between the knee lines, above the curve (it ends at 1 on the right)
            ax.text(float(np.sqrt(a * b)), 0.8, f"slope\n{text}", ha="center", va="center", fontsize=7.5,
                    color="0.25")
    ax.set_ylim(0, 1.2)
    key = "; ".join(n for n in names)
    ax.set(xlabel="illuminance on the sensor (lux, log scale)", ylabel="output / max output (linear)")
    ax.set_title(f"bold sensor: linear output on log illuminance\nslope = output per lux relative to the start: "
                 f"compressed, not saturated\n{key}", fontsize=8.5)
    ax.grid(True, which="both", alpha=0.3)


def snr_figure(curves: dict, title: str = "SNR vs illuminance"):
    """SNR in dB vs illuminance (input-referred for frame sensors, interval SNR for spikes).

    Curves stop where SNR means nothing: below SNR = 1 (0 dB) and past saturation (see
    :func:`meaningful`); saturation is marked with a cross."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    crossed = False
    for j, (name, c) in enumerate(curves.items()):
        snr = np.asarray(c["snr"], dtype=np.float64)
        lux = np.asarray(c["lux"])
        ok = meaningful(c) if "output" in c else (np.isfinite(snr) & (snr >= 1.0))
        ax.semilogx(lux[ok], 20 * np.log10(snr[ok]), label=name, color=f"C{j}")
        if "output" in c and ok.any() and saturates(c):
            last = np.nonzero(ok)[0][-1]
            ax.plot(lux[last], 20 * np.log10(snr[last]), "x", color=f"C{j}", ms=8)
            crossed = True
    if crossed:
        ax.plot([], [], "kx", label="last point before saturation")
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


# ----------------------------------------------------------------------------- seed 001 figures

def rpd_fig7_figure(codes=(40, 48, 56, 64, 72, 80, 88, 96), first_fraction: float = 5 / 6, barrier=None,
                    full_well_electrons: float = 10_000.0, gain_dn_per_e: float = 0.0748,
                    saturating_exposure_s: float = 100e-6):
    """Seed 001 Fig. 7 from the model: output against exposure (Iclk counts) at one light for
    several Rpd segment voltages; every curve follows the same line until its clamp, a
    higher voltage clamps lower, then all rise with the same slope to saturation."""
    from viform.sensors.segmented import (
        ICLK_HZ,
        RpdBarrier,
        exposure_s_from_iclk,
        response_vs_exposure_dn,
        rpd_voltage_v,
    )

    plt = _plt()
    barrier = barrier or RpdBarrier()
    counts = np.linspace(0, 3.0 * saturating_exposure_s * ICLK_HZ, 400)
    rate = full_well_electrons / saturating_exposure_s
    fig, ax = plt.subplots(figsize=(7.5, 4.4))
    cmap = plt.get_cmap("viridis")
    for i, code in enumerate(codes):
        v = rpd_voltage_v(code)
        b = barrier.clamp_fraction(v) * full_well_electrons
        dn = response_vs_exposure_dn(rate, exposure_s_from_iclk(counts), first_fraction, b, full_well_electrons,
                                     gain_dn_per_e)
        ax.plot(counts, dn, color=cmap(i / max(1, len(codes) - 1)),
                label=f"code {code} (0x{code:02X}) = {v:.3f} V, clamp {b / full_well_electrons:.2f} FW")
    ax.set(xlabel="exposure (Iclk counts, 48 MHz = 20.83 ns)", ylabel="output (DN above black)",
           title=f"Output against exposure at one light, two segments (first {first_fraction:.3g} clamped)")
    ax.legend(fontsize=7, title="Rpd segment voltage", title_fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def fraction_family_figure(barrier_fw: float = 5 / 12, f1_max: float = 5 / 6, normal_saturation: float = 30.0,
                           full_scale_dn: float = 748.0):
    """Seed 001 Fig. 8 from the model: output against intensity (the seed's units; the normal
    mode saturates at 30) for clamped-segment fractions k/8 of the largest (k = 0 … 8), one
    barrier. All curves coincide below the first knee; the range grows with k."""
    from viform.sensors.segmented import segmented_charge_electrons

    plt = _plt()
    x = np.linspace(0, 120, 600)
    rate = x / normal_saturation  # full wells per exposure
    fig, ax = plt.subplots(figsize=(7.5, 4.4))
    cmap = plt.get_cmap("plasma")
    for k in range(9):
        f1 = k / 8 * f1_max
        if k == 0:
            q = np.minimum(rate, 1.0)
        else:
            q = np.minimum(segmented_charge_electrons(rate, (f1, 1 - f1), (barrier_fw, 1.0)), 1.0)
        sat = x[np.argmax(q >= 1.0)] if (q >= 1.0).any() else float("nan")
        binds = 0 < k and f1 > barrier_fw
        # the barrier binds at r = b/f1 full wells per exposure, where the output (nothing lost
        # yet) is b/f1 of the full scale: 374 DN only for the fitted 8/8
        knee_dn = barrier_fw / f1 * full_scale_dn if binds else None
        ax.plot(x, q * full_scale_dn, color=cmap(k / 9), label=f"{k}/8 (f1 = {f1:.3f}): saturates at {sat:.0f}"
                + (f", knee {knee_dn:.0f} DN" if binds else "") + (" (barrier never binds)" if 0 < k and not binds
                                                                    else ""))
        if binds:
            ax.plot([barrier_fw / f1 * normal_saturation], [knee_dn], "o", ms=4, color=cmap(k / 9))
    ax.axhline(barrier_fw / f1_max * full_scale_dn, color="0.5", ls=":", lw=0.8)
    ax.text(1, barrier_fw / f1_max * full_scale_dn + 8, "374 DN: the 8/8 knee (the barrier was fitted there)",
            fontsize=7, color="0.4")
    ax.set(xlabel="light intensity (paper's units; normal mode saturates at 30)", ylabel="output (DN above black)",
           title=f"Segment-fraction family, barrier {barrier_fw:.3f} FW (paper Fig. 8: 30 → 105 at 8/8)\n"
                 "one barrier for all: a shorter first segment f1 reaches it at a higher light, so the knee "
                 "(output b/f1) rises", )
    ax.title.set_fontsize(9)
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def three_segment_family_figure(rows, full_scale_dn: float = 748.0):
    """The one-parameter family of three-segment fits of seed 001 Fig. 9: every member passes
    through 348 DN, 669.8 DN and saturates at 440; they differ in where the second knee is."""
    from viform.sensors.segmented import segmented_charge_electrons

    plt = _plt()
    x = np.geomspace(1, 600, 800)
    rate = x / 35.0
    fig, ax = plt.subplots(figsize=(7.5, 4.4))
    for j, r in enumerate(rows):
        q = np.minimum(segmented_charge_electrons(rate, r["fractions"], (*r["barriers_fw"], 1.0)), 1.0)
        f = r["fractions"]
        ax.semilogx(x, q * full_scale_dn, color=f"C{j}",
                    label=f"f = {f[0]:.3f}:{f[1]:.3f}:{f[2]:.3f}, b = {r['barriers_fw'][0]:.3f}/"
                          f"{r['barriers_fw'][1]:.3f}; knee 2 at {r['knee2_intensity_units']:.0f}")
        ax.plot([r["knee2_intensity_units"]], [669.8], "o", color=f"C{j}", ms=4)
    for y in (348, 669.8):
        ax.axhline(y, color="0.5", ls=":", lw=0.8)
    ax.axvline(440, color="0.5", ls="--", lw=0.8)
    ax.axvline(35, color="0.7", ls="--", lw=0.8)
    ax.set(xlabel="light intensity (paper's units; normal mode saturates at 35)", ylabel="output (DN above black)",
           title="Three-segment fits of paper Fig. 9 (knees 348 / 669.8 DN, saturation 440):\n"
                 "a one-parameter family")
    ax.legend(fontsize=6.5, title="the second knee's intensity pins the member", title_fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def snr_knees_figure(sensor, normal, spread_sensor=None, measured: dict | None = None):
    """SNR against illuminance of a segmented sensor and the normal mode (analytic, shot +
    read noise), the dip at each knee annotated; optionally with a barrier spread (fixed
    pattern above the knees) and measured points."""
    from viform.sensors.segmented import expected_snr, snr_knee_dips_db

    plt = _plt()
    p = sensor.parameters
    lux = np.geomspace(0.3, 2e5, 1500)
    rate = p.optics.electrons_per_s(lux) + p.dark_current_e_per_s
    fig, ax = plt.subplots(figsize=(7.5, 4.4))
    sn = expected_snr(rate, [normal.exposure_s], [p.full_well_electrons], p.read_noise_electrons)
    ax.semilogx(lux, 20 * np.log10(sn), "k--", lw=1, label="normal mode (saturates)")
    s = expected_snr(rate, sensor.segment_times_s, sensor.clamp_levels_electrons, p.read_noise_electrons)
    ax.semilogx(lux, 20 * np.log10(s), "C0", lw=1.8, label="segmented (shot + read noise)")
    if spread_sensor is not None:
        s2 = expected_snr(rate, sensor.segment_times_s, sensor.clamp_levels_electrons, p.read_noise_electrons,
                          spread_sensor.barrier_spread_fraction)
        ax.semilogx(lux, 20 * np.log10(s2), "C3", lw=1.2,
                    label=f"segmented, barrier spread {100 * spread_sensor.barrier_spread_fraction:g} % (FPN)")
    if measured is not None:
        m = np.asarray(measured["snr"], dtype=np.float64)
        ok = meaningful(measured)
        ax.semilogx(np.asarray(measured["lux"])[ok], 20 * np.log10(m[ok]), "C0.", ms=3,
                    label="simulated (temporal + spatial)")
    dips = snr_knee_dips_db(sensor.segment_times_s)
    for k, x in enumerate(sensor.knee_lux()[:-1]):
        y = 20 * np.log10(np.nanmax(s[lux <= x]))
        ax.annotate(f"knee {k + 1}: −{dips[k]:.1f} dB", xy=(x, y), fontsize=8,
                    xytext=(x * (0.05 if k == 0 else 2.5), y + 2 + 2 * k), arrowprops=dict(arrowstyle="->", lw=0.7))
    ax.set_ylim(bottom=0)
    ax.set(xlabel="illuminance on the sensor (lux)", ylabel="SNR (dB), input-referred",
           title="SNR of the segmented exposure: the paper claims no SNR loss; each knee costs SNR")
    ax.legend(fontsize=7.5, loc="lower right")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- seed 003 figure 5

def paper003_fig5(size: int = 16, seed: int = 0, currents_a=None) -> dict:
    """Seed 003 Fig. 5 from the model: the plain 4T (a), the lateral-overflow capacitor
    pixel (b) and the conditional-overflow pixel (c), each with its DR from SNR = 1 (E1, E2)
    to its plateau (E3, E4), against the photocurrent. Returns the curves and the DRs."""
    from viform.light.radiometry import ELEMENTARY_CHARGE_C
    from viform.measure.emva1288 import dynamic_range_from_response
    from viform.sensors.catalog import make_sensor

    currents = np.geomspace(1e-16, 3e-8, 150) if currents_a is None else np.asarray(currents_a)
    out = {}
    for key, label in (("seed003-4t", "(a) plain 4T"), ("seed003-lofic", "(b) lateral overflow capacitor"),
                       ("seed003-overflow", "(c) conditional overflow (this paper)")):
        kw = {"height": size, "width": size} if key == "seed003-overflow" else {}
        s = make_sensor(key, **kw)
        lux = s.parameters.optics.lux_from_electrons_per_s(currents / ELEMENTARY_CHARGE_C)
        c = frame_response_curve(s, lux, size=size, seed=seed)
        dr = dynamic_range_from_response(c["raw"])
        c["current_a"] = currents
        out[label] = {"curve": c, "i_min_a": float(np.interp(dr["lux_min"], lux, currents)),
                      "i_sat_a": float(np.interp(dr["lux_sat"], lux, currents)),
                      "dynamic_range_db": float(dr["dynamic_range_db"])}
    return out


def paper003_fig5_figure(res: dict):
    """Output (fraction of its own maximum) against photocurrent, with E_min / E_sat marked."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for j, (label, r) in enumerate(res.items()):
        c = r["curve"]
        snr = np.asarray(c["snr"], dtype=np.float64)
        ok = np.isfinite(snr) & (snr >= 1.0)
        ax.loglog(c["current_a"][ok], np.asarray(c["output"])[ok], color=f"C{j}", lw=1.8,
                  label=f"{label}: DR {r['dynamic_range_db']:.1f} dB "
                        f"({r['i_min_a']:.2g} – {r['i_sat_a']:.2g} A)")
        for x in (r["i_min_a"], r["i_sat_a"]):
            ax.axvline(x, color=f"C{j}", ls=":", lw=0.8)
    ax.set(xlabel="photocurrent (A)", ylabel="output / its maximum (from SNR = 1)",
           title="Paper Fig. 5 from the model: each curve starts at SNR = 1 (E1, E2) and ends at its plateau")
    ax.title.set_fontsize(9.5)
    ax.legend(fontsize=7.5, loc="lower right")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig
