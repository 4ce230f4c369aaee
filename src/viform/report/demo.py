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
             started_s: float | None = None) -> dict:
    """Run the comparison on the dilemma scene; write the report; return the metrics document."""
    from viform.report.compare_report import compare

    return compare("dilemma", out_dir, None, duration_s, DEMO_HEIGHT, DEMO_WIDTH, seed, progress=progress,
                   command="viform demo", started_s=started_s)
