"""Figures for the spike continuous display, pass-through and light communication (seed 000 §7).

All files are written through :func:`viform._io.save_figure`.
"""

from __future__ import annotations

import numpy as np

from viform._io import save_figure


def _figure(*args, **kw):
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kw)


# ------------------------------------------------------------------ light communication

def plot_ber_sweeps(path, sweeps: dict, modulation: str) -> None:
    """BER against bit rate, distance (received light) and ambient light, one panel each."""
    fig, axes = _figure(1, 3, figsize=(13, 3.8))
    for ax, (name, rows) in zip(axes, sweeps.items(), strict=False):
        x = np.array([r[name] for r in rows], float)
        y = np.array([r["ber"] for r in rows], float)
        n = rows[0]["n_bits"] if rows else 1
        floor = 0.5 / n
        ax.plot(np.maximum(x, 1e-3), np.maximum(y, floor), "o-", label=f"{modulation} BER (0 errors drawn at ½/n)")
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_ylim(floor / 2, 1)
        ax.set_xlabel({"bitrate_bps": "bit rate (bit/s)", "distance_m": "distance (m)",
                       "ambient_lux": "ambient on sensor (lux; 0 drawn at 1e-3)"}[name])
        ax.set_ylabel("bit-error rate")
        ax.grid(True, which="both", alpha=0.3)
        background = name == "ambient_lux"
        key = "background_spikes_per_slot_pixel" if background else "expected_spikes_per_on_slot_pixel"
        ax2 = ax.twinx()
        ax2.plot(np.maximum(x, 1e-3), [r[key] for r in rows], "s--", color="tab:gray", alpha=0.6,
                 label="spikes per slot and pixel (right axis)")
        ax2.set_yscale("log")
        ax2.set_ylabel("background spikes / slot" if background else "signal spikes / on slot")
    # one legend for the figure: the BER line and the spikes-per-slot line of the last panel
    handles = [ax.get_lines()[0], ax2.get_lines()[0]]
    fig.legend(handles, [h.get_label() for h in handles], loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle("Spike-camera light link: bit-error rate against bit rate, distance and ambient light")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    save_figure(path, fig)


def plot_link_raster(path, result, spikes: np.ndarray, clock_hz: float, max_slots: int = 60) -> None:
    """The LED's slot levels, the brightest pixel's spikes and the per-slot counts with the decisions."""
    fig, axes = _figure(2, 1, figsize=(11, 4.6), sharex=True)
    slots = result.slot_levels[:max_slots]
    slot_s = result.slot_s
    t_slots = np.arange(slots.size) * slot_s
    flat = spikes.reshape(spikes.shape[0], -1)
    best = int(np.argmax(flat.sum(axis=0)))
    n_ticks = int(np.ceil((slots.size * slot_s) * clock_hz))
    # spikes of the payload, on payload time (tick k read at its end, drawn at its middle)
    k0 = int(np.floor(result.payload_start_s * clock_hz))
    k = np.nonzero(flat[k0:k0 + n_ticks + 1, best])[0] + k0
    t_spk = (k + 0.5) / clock_hz - result.payload_start_s
    axes[0].step(t_slots * 1e3, slots, where="post", label="LED on/off (payload)")
    axes[0].vlines(t_spk * 1e3, 1.1, 1.5, color="k", lw=0.8,
                   label="spikes, brightest pixel")
    axes[0].set_ylabel("LED level (on = 1)")
    axes[0].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    counts = result.counts[:max_slots]
    axes[1].bar(t_slots * 1e3, counts, width=slot_s * 1e3 * 0.9, align="edge", label="spikes per slot (pixels used)")
    axes[1].axhline(result.threshold, color="r", ls="--", lw=0.8, label="OOK threshold")
    axes[1].set_xlabel("time from payload start (ms)")
    axes[1].set_ylabel("spikes per slot")
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.suptitle(f"{result.modulation} at {result.bitrate_bps:g} bit/s: {result.bit_errors} errors "
                 f"in {result.n_bits} bits")
    fig.tight_layout()
    save_figure(path, fig)


# ------------------------------------------------------------------ displays

#: Line styles of the hold displays: their steps often coincide (120 Hz refreshes at every
#: 60 Hz refresh), so the 60 Hz line is wide and pale and the 120 Hz one dashed on top of it.
_HOLD_STYLES = {
    "hold 60 Hz": {"lw": 4.0, "alpha": 0.45, "color": "tab:orange", "zorder": 2},
    "hold 120 Hz": {"lw": 1.4, "ls": "--", "color": "tab:green", "zorder": 3},
}

def plot_display_light_vs_time(path, comparison: dict, pixel_col: int | None = None, window_s: float = 1e-3) -> None:
    """Light at one pixel over time: the scene, the spike display (averaged over ``window_s``)
    and the hold displays."""
    arrays = comparison["arrays"]
    clock = comparison["clock_hz"]
    n = arrays["truth"].shape[0]
    col = pixel_col if pixel_col is not None else arrays["truth"].shape[2] // 2
    t = (np.arange(n) + 0.5) / clock * 1e3
    fig, ax = _figure(figsize=(10, 4))
    w = max(1, int(round(window_s * clock)))
    for name, e in arrays.items():
        trace = e[:, :, col].mean(axis=1, dtype=np.float64)
        if name == "spike":
            m = (n // w) * w
            tb = t[:m].reshape(-1, w).mean(axis=1)
            ax.step(tb, trace[:m].reshape(-1, w).mean(axis=1), where="mid", lw=1.2,
                    label=f"spike display ({window_s * 1e3:g} ms mean, rows averaged)")
        elif name == "truth":
            ax.plot(t, trace, "k-", lw=2.2, alpha=0.35, label="scene (truth)")
        else:
            # hold displays can step at the same instant: thick solid under thin dashed, both visible
            style = _HOLD_STYLES.get(name, {"lw": 1.2})
            ax.plot(t, trace, label=name, **style)
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("light (lux, sensor-plane units)")
    ax.set_title(f"column {col}: moving bars at {comparison['scene']['velocity_px_per_s']:g} px/s")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(path, fig)


def plot_tracked_edges(path, comparison: dict) -> None:
    """What a tracking eye integrates over its integration time, near one rising edge."""
    fig, ax = _figure(figsize=(8, 4))
    edge = comparison["edge_u_px"]
    for name, row in comparison["displays"].items():
        u, prof = row["profile"]
        sel = np.abs(u - edge) < comparison["scene"]["period_px"] / 2
        style = {"lw": 2.2, "alpha": 0.35, "color": "k"} if name == "truth" else {"lw": 1.2}
        ax.plot(u[sel] - edge, prof[sel], label=f"{name}: 10–90 % {row['tracked_edge_width_px']:.2f} px", **style)
    ax.set_xlabel("retinal position relative to the edge (px)")
    ax.set_ylabel("integrated light (lux)")
    ax.set_title(f"tracking eye, {comparison['eye_integration_s'] * 1e3:.3g} ms integration")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(path, fig)


def plot_passthrough_step(path, result: dict) -> None:
    """Step response of the spike pass-through and of the conventional 60 Hz pipe."""
    a = result["arrays"]
    clock = result["clock_hz"]
    k = a["step_tick"]
    fig, axes = _figure(1, 2, figsize=(11, 3.8))
    for ax, span in zip(axes, (int(0.033 * clock), 20), strict=True):
        sl = slice(max(0, k - span // 4), min(k + span, a["step_truth"].shape[0]))
        t = (np.arange(sl.start, sl.stop) + 0.5 - k) / clock * 1e3
        for name, key, style in (
                ("spike pass-through", "step_spike", {"color": "tab:orange", "lw": 1.0, "zorder": 2}),
                ("60 Hz camera → 60 Hz display", "step_conventional", {"color": "tab:green", "lw": 1.6, "zorder": 3}),
                # the scene on top, dashed, so the noisy spike trace cannot hide it
                ("scene", "step_truth", {"color": "k", "lw": 1.4, "ls": "--", "zorder": 4})):
            ax.step(t, a[key][sl].reshape(t.size, -1).mean(axis=1), where="mid", label=name, **style)
        ax.set_xlabel("time from the step (ms)")
        ax.set_ylabel("light (lux), pixels averaged")
    axes[0].legend(fontsize=8, loc="lower right")
    axes[0].set_title("33 ms around the step")
    axes[1].set_title("zoom: the spike pipe, tick by tick")
    fig.suptitle(f"pass-through latency: spike {result['spike']['latency_s'] * 1e6:.3g} µs, "
                 f"conventional {result['conventional']['latency_s'] * 1e3:.3g} ms")
    fig.tight_layout()
    save_figure(path, fig)
