"""Figures of the example scene descriptions: the light (log scale, lux) and the flow truth of each.

Run: ``python examples/scenes/figures.py [OUT_FOLDER]`` (default docs/scenes/): one PNG per description.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from viform._io import save_figure  # noqa: E402
from viform.light.catalog import load_scene  # noqa: E402

HERE = Path(__file__).parent
T0_S, DT_S = 0.02, 0.001


def flow_colour(flow: np.ndarray, valid: np.ndarray, max_px: float) -> np.ndarray:
    """Direction as hue, magnitude as saturation (white = still), black where the truth is invalid."""
    from matplotlib.colors import hsv_to_rgb

    dx, dy = flow
    hue = (np.arctan2(dy, dx) / (2 * np.pi)) % 1.0
    sat = np.clip(np.hypot(dx, dy) / max_px, 0, 1)
    rgb = hsv_to_rgb(np.stack([np.nan_to_num(hue), np.nan_to_num(sat), np.ones_like(hue)], axis=-1))
    rgb[~valid] = 0.0
    return rgb


def figure(path: Path, out: Path) -> Path:
    scene = load_scene(str(path))
    lux = scene.illuminance_lux(T0_S)
    flow = scene.optical_flow_px(T0_S, T0_S + DT_S)
    mag = np.hypot(*flow.flow_px)
    top = float(np.nanpercentile(mag[flow.valid], 99.5)) if flow.valid.any() else 1.0
    top = top if top > 0 else 1.0
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 3.6), constrained_layout=True)
    im = axes[0].imshow(np.log10(np.maximum(lux, 1e-3)), cmap="gray")
    fig.colorbar(im, ax=axes[0], label="log10 illuminance (lux)", shrink=0.85)
    axes[0].set_title(f"{scene.name}: light at t = {T0_S * 1e3:g} ms")
    for obj in scene.objects(T0_S):
        axes[0].add_patch(plt.Rectangle((obj.x_px - 0.5, obj.y_px - 0.5), obj.width_px, obj.height_px,
                                        fill=False, ec="tab:orange", lw=1))
        axes[0].text(obj.x_px, obj.y_px - 2, f"{obj.object_id} {obj.class_name}", color="tab:orange", fontsize=7)
    axes[1].imshow(flow_colour(flow.flow_px, flow.valid, top))
    axes[1].set_title(f"flow truth {T0_S * 1e3:g} → {(T0_S + DT_S) * 1e3:g} ms "
                      f"(white: still, full colour: {top:.2g} px; black: invalid)", fontsize=9)
    # a few arrows on a coarse grid, so direction reads without the colour wheel
    step = max(scene.width // 16, 1)
    ys, xs = np.mgrid[step // 2:scene.height:step, step // 2:scene.width:step]
    ok = flow.valid[ys, xs] & (mag[ys, xs] > 0.05 * top)
    axes[1].quiver(xs[ok], ys[ok], flow.flow_px[0][ys, xs][ok], -flow.flow_px[1][ys, xs][ok], color="k",
                   scale=top * 25, width=0.003)
    for ax in axes:
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
    target = out / f"{path.stem}.png"
    save_figure(target, fig)
    plt.close(fig)
    return target


def main(argv=None) -> list[Path]:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0]) if argv else HERE.parent.parent / "docs" / "scenes"
    out.mkdir(parents=True, exist_ok=True)
    return [figure(p, out) for p in sorted(HERE.glob("*.yaml"))]


if __name__ == "__main__":
    for p in main():
        print(p)
