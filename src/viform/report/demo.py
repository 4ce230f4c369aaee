"""``viform demo``: the dilemma scene shot by every sensor, compared with the truth.

Seed 000 §1 states the dilemma of timed-exposure cameras (high speed against high dynamic
range); the demo shows it on :class:`~viform.light.dilemma.DilemmaScene` with every sensor
the project models (see :mod:`viform.report.compare_report`).
"""

from __future__ import annotations

#: Resolution of the demo scene: 64 rows is what the seed 003 column-shared overflow unit
#: can serve at 30 fps (65 rows × 0.51 ms ≤ 33.3 ms), so every sensor takes part.
DEMO_HEIGHT, DEMO_WIDTH = 64, 128


def run_demo(out_dir, duration_s: float = 0.04, seed: int = 0, progress: bool = True,
             started_s: float | None = None, scene_options: dict | None = None) -> dict:
    """Run the comparison on the dilemma scene (its parameters ``scene_options``); write the report; return
    the metrics document."""
    from viform.report.compare_report import compare

    return compare("dilemma", out_dir, None, duration_s, DEMO_HEIGHT, DEMO_WIDTH, seed, progress=progress,
                   command="viform demo", started_s=started_s, scene_options=scene_options)


#: The demo's closing sweep: the spike chip's 16 threshold levels (at its 40 kHz clock), and the main
#: knob of the CMOS (exposure) and of the overflow pixel (its capacitor), 10 settings each.
DEMO_SWEEP = {"spikeone": ["spikeone:threshold_level=all"], "cmos": ["cmos:exposure_s=log:2e-5:3.3e-2:10"],
              "seed003-overflow": ["seed003-overflow:overflow_capacitance_f=log:2e-14:2e-11:10"]}


def demo_demands(scene) -> str:
    """The dilemma's two demands as ``--require`` text: its range (within
    :data:`~viform.measure.comparison.RANGE_MARGIN_DB`, as compare's verdict counts it) and its speed
    (integration time, :data:`~viform.measure.comparison.METRICS` ``time_resolution_s``, no longer than one
    pixel of the fastest motion)."""
    from viform.measure.comparison import RANGE_MARGIN_DB

    d = scene.demand()
    return (f"dr_captured_db>={d['dynamic_range_db'] - RANGE_MARGIN_DB:.0f},"
            f"time_resolution_s<={d['time_resolution_s']:.3g}")


def demo_demands_explained(scene) -> list[str]:
    """Where each demand of :func:`demo_demands` comes from, in words a reader needs no paper for."""
    from viform.measure.comparison import RANGE_MARGIN_DB

    d = scene.demand()
    return [f"range: the scene spans {d['dynamic_range_db']:.0f} dB ({d['min_lux']:.3g} to {d['max_lux']:,.0f} lux); "
            f"a sensor meets it from {d['dynamic_range_db'] - RANGE_MARGIN_DB:.0f} dB (within {RANGE_MARGIN_DB:.0f} "
            "dB, a factor of 2 in light, as the verdict above counts a range)",
            f"speed: a pixel integrates each reading over at most {d['time_resolution_s'] * 1e3:.3g} ms, the time its "
            f"fastest motion ({d['max_speed_px_per_s']:,.0f} px/s) takes to cross one pixel (a frame camera's "
            "exposure; a spike pixel's interval between spikes, median where the scene moves)"]


def run_demo_sweep(out_dir, duration_s: float = 0.04, seed: int = 0, progress: bool = True,
                   scene_options: dict | None = None) -> dict:
    """The designer's question on the demo scene: which setting meets both demands? (OUT/sweep/report.html)."""
    from pathlib import Path

    from viform.light.catalog import builtin_scene
    from viform.measure.sweep import make_plan
    from viform.report.sweep_report import run_sweep_report

    demands = demo_demands(builtin_scene("dilemma", DEMO_HEIGHT, DEMO_WIDTH, **(scene_options or {})))
    plan = make_plan("dilemma", list(DEMO_SWEEP), [v for vs in DEMO_SWEEP.values() for v in vs],
                     height=DEMO_HEIGHT, width=DEMO_WIDTH, duration_s=duration_s, seed=seed, require=demands,
                     scene_options=scene_options)
    notes = demo_demands_explained(builtin_scene("dilemma", DEMO_HEIGHT, DEMO_WIDTH, **(scene_options or {})))
    result = run_sweep_report(plan, Path(out_dir) / "sweep", workers=0, progress=progress, command="viform demo",
                              demand_notes=notes)
    result["demands_explained"] = notes
    return result
