"""Figures for range-gated imaging (seed 004): range–intensity profile, gated vs un-gated
images in fog, the three accumulation modes, CNR per target. All written via viform._io."""

from __future__ import annotations

import numpy as np

from viform._io import save_figure
from viform.light.active import ActiveScene, Medium


def range_intensity_profile(
    sensor, medium: Medium | None = None, reflectance: float = 0.3, r_max_m: float | None = None, n: int = 600
) -> dict:
    """Per-pulse electrons vs range for a Lambertian surface and fog backscatter density.

    Returns ranges, gated and un-gated surface electrons, and the backscatter per metre
    of path (gated, un-gated) in ``medium``.
    """
    t = sensor.timing
    r_max = r_max_m or max(2.0 * t.range_window_m[1], 100.0)
    r = np.linspace(1.0, r_max, n)
    med = medium or Medium()
    scene = ActiveScene(range_m=r[None, :], reflectance=reflectance, medium=med)
    g = sensor.geometry
    gated = g.surface_electrons(scene, t.open_s, t.close_s)[0]
    ungated = g.surface_electrons(scene)[0]
    bs_g = np.gradient(g.backscatter_electrons(scene, t.open_s, t.close_s)[0], r)
    bs_u = np.gradient(g.backscatter_electrons(scene)[0], r)
    return {
        "range_m": r,
        "surface_gated": gated,
        "surface_ungated": ungated,
        "backscatter_gated_per_m": bs_g,
        "backscatter_ungated_per_m": bs_u,
        "gate_window_m": t.range_window_m,
    }


def plot_range_intensity(path, profile: dict, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    r = profile["range_m"]
    a.semilogy(r, np.maximum(profile["surface_ungated"], 1e-12), "k--", label="un-gated")
    a.semilogy(r, np.maximum(profile["surface_gated"], 1e-12), "C0", label="gated")
    # no surface signal at all (a fog that hides everything) still gets a positive log range
    surface_top = max(float(profile["surface_ungated"].max()) * 3, 1e-8)
    a.set_ylim(min(max(1e-9, float(profile["surface_ungated"].min()) / 10), surface_top / 10), surface_top)
    a.set(xlabel="range (m)", ylabel="e⁻ per pulse per pixel", title="Lambertian surface")
    lo, hi = profile["gate_window_m"]
    for ax in (a, b):
        ax.axvspan(lo, hi, color="C1", alpha=0.15, label="gate")
    b.semilogy(r, np.maximum(profile["backscatter_ungated_per_m"], 1e-15), "k--", label="un-gated")
    b.semilogy(r, np.maximum(profile["backscatter_gated_per_m"], 1e-15), "C0", label="gated")
    top = max(profile["backscatter_ungated_per_m"].max(), 1e-12)
    b.set_ylim(top * 1e-8, top * 3)
    b.set(xlabel="range (m)", ylabel="e⁻ per pulse per metre of path", title="medium backscatter")
    a.legend()
    b.legend()
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(path, fig)


def plot_images(path, images: dict, title: str = "", percentile: float = 99.5, shared_scale: bool = False) -> None:
    """Side-by-side images (electrons) stretched to the [100 − p, p] percentile range.

    With ``shared_scale`` one range, taken over all images together, is used for every
    panel, so a brighter background (e.g. the fog veil of an un-gated frame, seed 004
    introduction) shows as brighter instead of being stretched away; otherwise each
    image gets its own range.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(images)
    common = None
    if shared_scale:
        common = np.percentile(np.concatenate([np.ravel(im) for im in images.values()]),
                               [100 - percentile, percentile])
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n + (1.0 if shared_scale else 0.0), 3.4), squeeze=False,
                             layout="constrained")
    for ax, (name, img) in zip(axes[0], images.items(), strict=True):
        lo, hi = common if common is not None else np.percentile(img, [100 - percentile, percentile])
        im = ax.imshow(img, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1)
        ax.set_title(name, fontsize=9)
        ax.axis("off")
    if shared_scale:
        fig.colorbar(im, ax=axes[0].tolist(), shrink=0.85, label="electrons per pixel (one scale)")
    fig.suptitle(title)
    save_figure(path, fig)


def plot_modes(path, images: dict, full_well_electrons: float, title: str = "") -> None:
    """The modes' frames on ONE logarithmic electron scale (1 e⁻ … the well) with a colour bar,
    so a saturated frame shows as saturated, not as stretched noise."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    n = len(images)
    fig, axes = plt.subplots(1, n, figsize=(3.7 * n + 1.2, 3.4), squeeze=False)
    norm = LogNorm(vmin=1.0, vmax=float(full_well_electrons))
    for ax, (name, img) in zip(axes[0], images.items(), strict=True):
        im = ax.imshow(np.clip(img, 1.0, None), cmap="gray", norm=norm, interpolation="nearest")
        sat = float(np.mean(img >= 0.98 * full_well_electrons))
        ax.set_title(f"{name}\n{100 * sat:.0f} % of pixels saturated", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.85, label="electrons per pixel (log; one scale for all)")
    fig.suptitle(title, fontsize=10)
    save_figure(path, fig)


def plot_cnr(path, rows: list[dict], threshold: float, title: str = "") -> None:
    """Grouped bars: glint contrast-to-noise ratio per target (x) for each mode (colour);
    symmetric-log axis so a CNR of 0 is drawn as 0. A saturated target (glint and its
    surround both clipped, so its CNR is 0 or meaningless) is drawn as a full-height hollow
    hatched bar labelled "saturated", and a CNR of 0 is written "0", so no mode's bar is
    invisible. ``rows`` have 'target', 'mode', 'cnr' and optionally 'saturated'."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    targets = list(dict.fromkeys(r["target"] for r in rows))
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    fig, ax = plt.subplots(figsize=(9.5, 4.0))
    w = 0.8 / len(modes)
    top = 3.0 * max([threshold, *[float(r["cnr"]) for r in rows if np.isfinite(r["cnr"])]])
    any_sat = False
    for j, m in enumerate(modes):
        for i, t in enumerate(targets):
            r = next((r for r in rows if r["target"] == t and r["mode"] == m), None)
            if r is None:
                continue
            x = i + (j - (len(modes) - 1) / 2) * w
            v = max(float(r["cnr"]), 0.0)
            if r.get("saturated"):
                any_sat = True
                ax.bar(x, top, w * 0.95, facecolor="none", edgecolor=f"C{j}", hatch="//", lw=1.0)
                ax.text(x, 0.3, f"saturated (CNR {v:.2g})", rotation=90, ha="center", va="bottom", fontsize=7,
                        color=f"C{j}", bbox=dict(facecolor="white", edgecolor="none", pad=1.0))
            else:
                ax.bar(x, v, w * 0.95, color=f"C{j}", edgecolor="k", lw=0.4)
                if v < 0.05:
                    ax.text(x, 0.02, "0", ha="center", va="bottom", fontsize=7, color=f"C{j}")
        ax.bar(np.nan, 0, color=f"C{j}", label=m)  # legend entry per mode
    if any_sat:
        ax.bar(np.nan, 0, facecolor="none", edgecolor="k", hatch="//", label="saturated (drawn full height)")
    ax.axhline(threshold, color="k", ls="--", lw=1, label=f"stands out: CNR ≥ {threshold:g}")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(0, top)
    ax.set_xticks(range(len(targets)), targets)
    ax.set_xlabel("reflector range")
    ax.set_ylabel("glint contrast-to-noise ratio\n(linear 0–1, log above)")
    ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    save_figure(path, fig)


def plot_gate_sweep(path, sweep: dict) -> None:
    """Glint CNR of each reflector against the gate's near range (the seed's field
    procedure: raise the range until the glint vanishes), true ranges marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4))
    g = sweep["gates_m"]
    for j, (lab, rng) in enumerate(zip(sweep["labels"], sweep["ranges_m"], strict=True)):
        ax.plot(g, np.maximum(sweep["visibility"][:, j], 0.0), color=f"C{j}", label=f"reflector at {lab}")
        ax.axvline(rng, color=f"C{j}", ls=":", lw=1)
        v = sweep["vanish_gate_m"][lab]
        if v is not None:
            ax.plot([v], [sweep["threshold"]], "v", color=f"C{j}", ms=7)
    ax.axhline(sweep["threshold"], color="k", ls="--", lw=1, label=f"stands out: CNR ≥ {sweep['threshold']:g}")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(0, None)
    ax.set_xlabel("gate near range R (m)  — dotted: true range; ▼: glint vanishes")
    ax.set_ylabel("glint CNR: (peak − surround) / noise")
    ax.set_title(f"Gate sweep, X = {sweep['pulses']} pulses: a glint vanishes 20–30 m (≈ cτ/2) "
                 "beyond its range", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(path, fig)


def plot_depth(path, depth: dict, title: str = "") -> None:
    """True range, range from the gate sweep and its error (m), plus the signal against the
    gate range for a few pixels (the range–intensity profile the depth is read from)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    true = np.where(np.isfinite(depth["true_range_m"]), depth["true_range_m"], np.nan)
    est = depth["depth_m"]
    lo, hi = np.nanpercentile(true, [1, 99])
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.9), layout="constrained",
                             gridspec_kw={"width_ratios": [1, 1, 1, 1.15]})
    for ax, img, name in ((axes[0], true, "true range"), (axes[1], est, "range from the gate sweep")):
        im = ax.imshow(img, cmap="viridis", vmin=lo, vmax=hi, interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[1], shrink=0.8, label="range (m), same scale as the true range")
    err = est - true
    e = float(np.nanpercentile(np.abs(err), 95)) if np.isfinite(err).any() else 1.0
    im2 = axes[2].imshow(err, cmap="RdBu_r", vmin=-e, vmax=e, interpolation="nearest")
    med = float(np.nanmedian(np.abs(err))) if np.isfinite(err).any() else float("nan")
    axes[2].set_title(f"error, median |e| {med:.2f} m\n(red blobs: the reflectors' halos)", fontsize=9)
    axes[2].set_xticks([])
    axes[2].set_yticks([])
    fig.colorbar(im2, ax=axes[2], shrink=0.8, label="estimated − true (m)")
    g = depth["gates_m"]
    s = depth["frames_electrons"]
    h, w = true.shape
    picks = [(h - 2, w // 2), (int(np.nanargmin(np.abs(true[:, int(0.5 * w)] - 52.0))), int(0.5 * w))]
    for k, (r, c) in enumerate(picks):
        axes[3].plot(g, s[:, r, c], color=f"C{k}", label=f"pixel ({r},{c}), true {true[r, c]:.1f} m")
        axes[3].axvline(true[r, c], color=f"C{k}", ls=":")
    axes[3].set_xlabel("gate near range R (m)")
    axes[3].set_ylabel("electrons per frame")
    axes[3].set_title("range–intensity profile (dotted: true range)", fontsize=9)
    axes[3].legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    save_figure(path, fig)
