"""Range-gated imaging (seed 004): the same field-test scene seen with the gate set at 150 m, by the
in-buffer accumulation of 20 laser pulses. Reflectors inside the gate stand out; nearer ones vanish.

Run: ``python examples/range_gated.py``.
"""

from viform.light import field_test_scene
from viform.measure.gated_metrics import expected_cnr
from viform.sensors import GatedInterlineCCD

scene = field_test_scene(ambient_lux=1e5, visibility_m=20e3)  # sunny day, clear air
ccd = GatedInterlineCCD(pulses=20, gate_range_m=150.0, mode="accumulate", frame_rate_hz=25.0)
near, far = ccd.timing.range_window_m
print(f"gate opens for light from {near:.0f} m to {far:.0f} m")
for reflector in scene.retroreflectors:
    cnr = expected_cnr(ccd, scene, reflector.row, reflector.col).cnr
    print(f"reflector at {reflector.range_m:5.0f} m: contrast-to-noise {cnr:7.1f}"
          f" → {'visible' if cnr >= 5 else 'not visible'}")
