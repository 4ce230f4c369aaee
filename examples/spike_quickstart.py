"""Quick start: a scene → the spike camera → an image at any instant → a plot.

Run: ``python examples/spike_quickstart.py [OUT_DIR]`` (writes quickstart.png there).
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from viform.imaging import accumulation_image, interval_image
from viform.light import TranslatingScene
from viform.sensors import SpikeSensor

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
scene = TranslatingScene(height=120, width=200, velocity_px_per_s=(2000.0, 0.0), min_lux=0.25, max_lux=2.0)
stream = SpikeSensor(threshold_electrons=100).capture(scene, duration_s=0.02, seed=1)  # 800 ticks at 40 kHz
acc = accumulation_image(stream, t_s=0.01, window_s=1e-3)  # 1 ms of spikes ending at 10 ms
ivl = interval_image(stream, t_s=0.01)  # light = Q/τ of the interval holding 10 ms
fig, axes = plt.subplots(1, 3, figsize=(12, 3), constrained_layout=True)
for ax, image, title in zip(axes, (scene.illuminance_lux(0.01), acc.lux, ivl.lux),
                            ("truth at 10 ms", "accumulation, 1 ms", "interval (Q/τ)"), strict=True):
    shown = ax.imshow(image, cmap="gray", vmin=0, vmax=2.2)
    ax.set_title(title)
    ax.axis("off")
fig.colorbar(shown, ax=axes, label="illuminance on the sensor (lux)")
fig.savefig(out / "quickstart.png", dpi=80)
print(f"{stream.shape[0]} ticks, {int(stream.spikes.sum())} spikes; wrote {out / 'quickstart.png'}")
