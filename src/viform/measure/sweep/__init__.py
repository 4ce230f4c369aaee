"""Design exploration: shoot one scene with a sensor at many settings, score each, find the one that meets demands.

``viform compare`` scores each sensor at its documented settings; a sweep asks the designer's
next question — *at which setting* would a sensor meet the scene's demands, and at what cost.
A sweep is a list of **points** (a sensor of the catalogue, :mod:`viform.sensors.catalog`, plus the
settings that differ from its default); every point is shot and scored exactly as
:mod:`viform.measure.comparison` does it (same estimates of light, same metrics), so a sweep's default
point equals ``viform compare``.

The package, by section:

* :mod:`~viform.measure.sweep.parameters` — what can be varied (:func:`sweep_parameters`) and the
  sensor at one setting (:func:`make_point_sensor`);
* :mod:`~viform.measure.sweep.specs` — value specs (:func:`parse_values`, :func:`parse_vary`),
  demands (:func:`parse_require`) and the metrics' directions (:data:`METRIC_DIRECTIONS`);
* :mod:`~viform.measure.sweep.plan` — the points, their seeds and the validated plan
  (:func:`make_plan`);
* :mod:`~viform.measure.sweep.store` — point records and images, ``sweep.zarr`` (:func:`read_table`),
  resuming;
* :mod:`~viform.measure.sweep.answer` — which setting meets the demands (:func:`answer`);
* :mod:`~viform.measure.sweep.run` — one point (:func:`run_point`) and the whole sweep (:func:`sweep`).

Use: ``plan = make_plan("dilemma", ["cmos"], ["exposure_s=log:1e-4:1e-2:5"], require="edge_width_px<=2")``
then ``doc = sweep(plan, "out-folder")``. Errors begin with the name of the parameter they are
about (``duration_s``, ``vary_texts``, ``workers`` …); the command line names its flags instead.

Results: ``sweep.zarr`` (one row per point: sensor, point id, every swept parameter's value,
every metric), ``sweep.json`` (the plan, the demands and the answer) and the report
(:mod:`viform.report.sweep_report`).
"""

from viform.measure.sweep.answer import _miss_text, _settings_text, answer, answer_sentences, scene_text
from viform.measure.sweep.parameters import (
    SWEEP_SENSORS,
    check_sensor,
    make_point_sensor,
    scene_parameters,
    sweep_parameters,
)
from viform.measure.sweep.plan import (
    MAX_DURATION_S,
    MAX_SPIKE_BYTES,
    SCENE_PREFIX,
    SEEDED_AS,
    SPIKE_IMAGES,
    SWEEP_FORMAT,
    SWEEP_VERSION,
    Point,
    SweepContext,
    SweepPlan,
    check_objects,
    make_plan,
    plan_points,
    point_seed,
    scene_settings,
    standard_vary,
    validate_inputs,
)
from viform.measure.sweep.run import (
    DEVICES,
    GUIDED_SHARE,
    SEEN_CNR,
    batches,
    check_device,
    run_point,
    run_points,
    run_sweep,
    sweep,
    tracking_scores,
)
from viform.measure.sweep.specs import (
    DEFAULT_OBJECTIVE,
    METRIC_DIRECTIONS,
    SCENE,
    Demand,
    check_objective,
    parse_require,
    parse_values,
    parse_vary,
)
from viform.measure.sweep.store import (
    POINTS_DIR,
    ContextMismatch,
    _finite,
    _restore,
    check_context,
    load_images,
    load_point,
    metric_columns,
    read_table,
    store_point,
    write_table,
)

__all__ = [
    "ContextMismatch", "DEFAULT_OBJECTIVE", "DEVICES", "GUIDED_SHARE", "Demand", "MAX_DURATION_S", "MAX_SPIKE_BYTES",
    "METRIC_DIRECTIONS", "POINTS_DIR", "Point", "SCENE", "SCENE_PREFIX", "SEEDED_AS", "SEEN_CNR", "SPIKE_IMAGES",
    "SWEEP_FORMAT", "SWEEP_SENSORS", "SWEEP_VERSION", "SweepContext", "SweepPlan", "_finite",
    "_restore", "_miss_text", "_settings_text", "answer", "answer_sentences", "batches", "check_context",
    "check_device", "check_objective", "check_objects", "check_sensor", "load_images", "load_point", "make_plan",
    "make_point_sensor", "metric_columns", "parse_require", "parse_values", "parse_vary", "plan_points",
    "point_seed", "read_table", "run_point", "run_points", "run_sweep", "scene_parameters", "scene_settings",
    "scene_text", "standard_vary", "store_point", "sweep", "sweep_parameters", "tracking_scores", "validate_inputs",
    "write_table",
]
