"""Every parameter a model document's table names exists (docs/range-gated.md, frame-sensors.md,
high-speed.md).

In those documents, each table whose header has a "parameter" or "field" column lists
parameters by name in backticks; where the table also has an "of" column, that names the class
(or function) the parameter belongs to, else the document's own classes are searched. A name
must be a dataclass field or a constructor (or function) parameter of that class: a model that
renames or drops a parameter, or a document that names one the model lacks, fails here.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"

#: The classes each document describes: every name its parameter tables use must be one of theirs.
CLASSES = {
    "range-gated.md": ["viform.sensors.gated_ccd.GatedInterlineCCD", "viform.sensors.gated_ccd.InterlineCCDParameters",
                       "viform.light.laser.PulsedLaser", "viform.light.laser.Receiver",
                       "viform.light.active.Medium"],
    "frame-sensors.md": ["viform.sensors.frame.FramePixelParameters", "viform.sensors.frame.FrameSensor",
                         "viform.sensors.segmented.SegmentedExposureSensor",
                         "viform.sensors.overflow.OverflowSensor", "viform.sensors.highspeed.HighSpeedCamera"],
    "high-speed.md": ["viform.sensors.highspeed.HighSpeedCamera", "viform.sensors.frame.FramePixelParameters",
                      "viform.sensors.highspeed_timing.ReadoutTiming",
                      "viform.isp.highspeed_pipeline.HighSpeedConfig"],
}
NAME = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)`")


def _load(path: str):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


def _names_of(obj) -> set[str]:
    names = set()
    if dataclasses.is_dataclass(obj):
        names |= {f.name for f in dataclasses.fields(obj)}
    target = obj.__init__ if inspect.isclass(obj) else obj
    names |= {p for p in inspect.signature(target).parameters if p not in ("self", "args", "kwargs")}
    return names


def _parameter_rows(text: str):
    """(parameter cell, "of" cell or None) for every row of every parameter table."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        rule = lines[i + 1] if i + 1 < len(lines) else ""
        if not line.startswith("|") or not rule.startswith("|") or not set(rule.replace("|", "").strip()) <= set("-: "):
            continue
        head = [c.strip().lower() for c in line.strip().strip("|").split("|")]
        column = next((j for j, c in enumerate(head) if c.split(" ")[0] in ("parameter", "field")), None)
        if column is None:
            continue
        of = head.index("of") if "of" in head else None
        for row in lines[i + 2:]:
            if not row.startswith("|"):
                break
            cells = [c.strip() for c in row.strip().strip("|").split("|")]
            yield cells[column], (cells[of] if of is not None and of < len(cells) else None)


@pytest.mark.parametrize("doc", sorted(CLASSES))
def test_every_parameter_a_table_names_exists(doc):
    text = (DOCS / doc).read_text()
    classes = {path.rpartition(".")[2]: _load(path) for path in CLASSES[doc]}
    known = set().union(*(_names_of(c) for c in classes.values()))
    checked = 0
    for cell, of in _parameter_rows(text):
        # a call like `interline_ccd_parameters(part)` names a function, not a parameter
        names = [m.group(1) for m in NAME.finditer(cell) if not cell[m.end():].startswith("(")]
        owner = NAME.search(of).group(1) if of and NAME.search(of) else None
        if owner is not None:
            assert owner in classes, f"{doc}: the table names class {owner!r}, not one the test knows"
        allowed = _names_of(classes[owner]) if owner else known
        for name in names:
            assert name in allowed, f"{doc}: `{name}` is not a parameter of {owner or ', '.join(classes)}"
            checked += 1
    assert checked >= 10, f"{doc}: expected a parameter table, found {checked} names"


def test_a_wrong_name_is_caught():
    """The check itself: a made-up name in a parameter table is reported."""
    text = "| parameter | of | what |\n|---|---|---|\n| `no_such_parameter_s` | `FrameSensor` | x |\n"
    rows = list(_parameter_rows(text))
    assert rows == [("`no_such_parameter_s`", "`FrameSensor`")]
    from viform.sensors.frame import FrameSensor

    assert "no_such_parameter_s" not in _names_of(FrameSensor)
    assert "exposure_s" in _names_of(FrameSensor)
