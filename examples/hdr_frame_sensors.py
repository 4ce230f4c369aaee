"""One HDR scene, three frame sensors: a conventional CMOS, segmented exposure (seed 001) and the
conditional overflow capacitor pixel (seed 003). Prints the fraction of saturated pixels and the
darkest / brightest illuminance each one resolves.

Run: ``python examples/hdr_frame_sensors.py``.
"""

import numpy as np

from viform.light import HDRScene
from viform.sensors import make_sensor

scene = HDRScene(height=32, width=64, min_lux=0.01, decades=6.0)  # 0.01 … 10,000 lux, left to right
truth_lux = scene.illuminance_lux(0.0)
print(f"{'sensor':<18}{'saturated':>10}{'lux range resolved (SNR > 1, not saturated)':>48}")
for name in ("cmos", "seed001-3seg", "seed003-overflow"):
    sensor = make_sensor(name)
    frames = sensor.capture(scene, duration_s=0.04, seed=3)
    dn = np.asarray(frames.frames_dn[0], dtype=float)
    max_dn = sensor.parameters.max_dn
    saturated = dn >= max_dn
    # a column is resolved where its pixels differ from the dark level by more than their noise
    dark = np.median(dn[:, :2])
    resolved = (np.abs(dn.mean(axis=0) - dark) > dn.std(axis=0)) & ~saturated.any(axis=0)
    columns = truth_lux[0, resolved]
    span = f"{columns.min():.3g} … {columns.max():.3g} lux" if columns.size else "none"
    print(f"{name:<18}{saturated.mean():>10.1%}{span:>48}")
