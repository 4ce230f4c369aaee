"""Measurement: score sensors on a scene, sweep their settings, characterize and calibrate them.

* Comparison (:mod:`viform.measure.comparison`): :func:`shoot` a scene with a catalogue sensor (its
  :class:`Shot`, the light it shows via :func:`light_estimates`), :func:`score` it on the
  :data:`METRICS` against the scene's truth, and :func:`verdict` says which sensor wins on what.
* Sweeps (:mod:`viform.measure.sweep`): :func:`make_plan` validates a :class:`SweepPlan`;
  ``viform.measure.sweep.sweep(plan, out)`` runs it and :func:`read_table` reads ``sweep.zarr`` back.
* Characterization: :func:`characterize_frame_sensor` (EMVA 1288), :func:`characterize_spike_sensor`,
  :func:`dynamic_range_db`, :func:`measure_spike_dynamic_range`.
* Calibration of a real spike recording: :func:`calibrate`, :func:`preset_from_calibration`.
* Tracking scores of a comparison: :func:`vision_scores`.

The names are imported on first use (:mod:`viform._lazy`): ``import viform.measure`` costs nothing.
"""

from viform import _lazy

__all__ = [
    "shoot", "score", "verdict", "Shot", "METRICS", "DEFAULT_SENSORS", "light_estimates",
    "make_plan", "SweepPlan", "read_table",
    "characterize_frame_sensor", "characterize_spike_sensor", "dynamic_range_db", "measure_spike_dynamic_range",
    "calibrate", "preset_from_calibration", "vision_scores",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "comparison": ["shoot", "score", "verdict", "Shot", "METRICS", "DEFAULT_SENSORS"],
    "estimates": ["light_estimates"],
    "sweep.plan": ["make_plan", "SweepPlan"],
    "sweep.store": ["read_table"],
    "emva1288": ["characterize_frame_sensor"],
    "spike_characterization": ["characterize_spike_sensor"],
    "dynamic_range": ["dynamic_range_db", "measure_spike_dynamic_range"],
    "calibration": ["calibrate", "preset_from_calibration"],
    "vision_comparison": ["vision_scores"],
})
