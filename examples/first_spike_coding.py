"""First-spike coding (seed 000 §5): compress a spike stream losslessly and get the same bits back.

Run: ``python examples/first_spike_coding.py [OUT_DIR]`` (writes stream.vfc there).
"""

import sys
from pathlib import Path

import numpy as np

from viform.coding import encode_source, open_coded
from viform.light import TranslatingScene
from viform.sensors import SpikeSensor

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
stream = SpikeSensor().capture(TranslatingScene(height=64, width=96, velocity_px_per_s=(500.0, 0.0)), 0.02, seed=2)
encode_source(stream, out / "stream.vfc", mode="strict")
decoded = open_coded(out / "stream.vfc").read_ticks(0, stream.n_ticks)
raw_bytes = stream.n_ticks * stream.height * stream.width / 8
coded_bytes = (out / "stream.vfc").stat().st_size
print(f"raw {raw_bytes / 1e3:.1f} kB → coded {coded_bytes / 1e3:.1f} kB ({raw_bytes / coded_bytes:.2f}× smaller); "
      f"bit-exact: {np.array_equal(decoded, stream.spikes)}")
