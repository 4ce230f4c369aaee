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
    a.set_ylim(max(1e-9, profile["surface_ungated"].min() / 10), profile["surface_ungated"].max() * 3)
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
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.2), squeeze=False)
    for ax, (name, img) in zip(axes[0], images.items(), strict=True):
        lo, hi = common if common is not None else np.percentile(img, [100 - percentile, percentile])
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1)
        ax.set_title(name, fontsize=9)
        ax.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(path, fig)


def plot_cnr(path, rows: list[dict], threshold: float, title: str = "") -> None:
    """Bar chart of CNR per target (rows with 'label' and 'cnr'), threshold line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    labels = [r["label"] for r in rows]
    vals = [max(r["cnr"], 1e-3) for r in rows]
    ax.bar(labels, vals, color=["C2" if v >= threshold else "C3" for v in vals])
    ax.axhline(threshold, color="k", ls="--", label=f"CNR = {threshold:g}")
    ax.set_yscale("log")
    ax.set_ylabel("CNR")
    ax.tick_params(axis="x", labelsize=8)
    ax.legend()
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    save_figure(path, fig)
