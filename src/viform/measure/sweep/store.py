"""Where a sweep keeps its results: one record and one image file per finished point, the table, the context.

Each finished point is written at once (``points/<id>.json`` + ``.npz``, atomically, the images
first: the record marks the point finished); a sweep run again in the same folder — killed, or
extended with more points — reuses every stored point made in the same context. ``sweep.zarr``
holds one row per point (sensor, point id, every swept parameter's value, every metric).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from viform._io import atomic_path, write_json
from viform._validate import ViformError, one_line
from viform.measure import comparison as cmp
from viform.measure.sweep.specs import METRIC_DIRECTIONS

#: Folder of the point records and images inside a sweep's folder.
POINTS_DIR = "points"


def _point_paths(out: Path, point_id: str) -> tuple[Path, Path]:
    return out / POINTS_DIR / f"{point_id}.json", out / POINTS_DIR / f"{point_id}.npz"


def store_point(out: Path, result: dict) -> None:
    """Write one finished point: its images first, then its record (the record marks it finished)."""
    rec = result["record"]
    js, npz = _point_paths(out, rec["point_id"])
    if result["images"] is not None:
        with atomic_path(npz) as tmp, open(tmp, "wb") as f:
            np.savez_compressed(f, lux=result["images"])
    write_json(js, _finite(rec))


def load_point(out: Path, point, context) -> dict | None:
    """The stored record of ``point`` made in ``context``, or None (missing, other context, damaged)."""
    js, npz = _point_paths(out, point.point_id)
    try:
        rec = json.loads(js.read_text())
    except (OSError, ValueError):
        return None
    if rec.get("context_sha256") != context.fingerprint() or rec.get("point_id") != point.point_id:
        return None
    if not rec.get("skipped") and not npz.is_file():
        return None
    rec["swept"] = dict(point.swept)  # this sweep's axes (a stored point may serve several sweeps)
    return _restore(rec)


def load_images(out: Path, point_id: str) -> np.ndarray | None:
    """The light estimates (instants × H × W, lux; NaN where under-exposed) of a stored point, or None."""
    npz = _point_paths(Path(out), point_id)[1]
    if not npz.is_file():
        return None
    with np.load(npz) as f:
        return f["lux"]


def _finite(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _restore(rec: dict) -> dict:
    rec["metrics"] = {k: (math.nan if v is None and k in METRIC_DIRECTIONS else v) for k, v in rec["metrics"].items()}
    return rec


def metric_columns(records) -> list[str]:
    """Numeric metric columns of a sweep: the known ones first, then any other numeric score."""
    seen = dict.fromkeys(METRIC_DIRECTIONS)
    for r in records:
        for k, v in r["metrics"].items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                seen.setdefault(k)
    return list(seen)


def write_table(path: Path, records, context) -> None:
    """``sweep.zarr``: one row per point (sensor, point_id, label, default, swept parameters, metrics)."""
    import zarr

    cols = metric_columns(records)
    params = sorted({n for r in records for n in r["swept"]})
    with atomic_path(path, directory=True) as tmp:
        root = zarr.open_group(str(tmp), mode="w")
        n = len(records)
        for name, values in (("sensor", [r["sensor"] for r in records]),
                             ("point_id", [r["point_id"] for r in records]),
                             ("label", [r["label"] for r in records])):
            column = root.create_array(name, shape=(n,), dtype=str)  # variable-length UTF-8
            column[:] = np.array(values, dtype=object)
        root.create_array("default", data=np.array([bool(r["default"]) for r in records]))
        for c in cols:
            root.create_array(f"metric/{c}", data=np.array(
                [_as_float(r["metrics"].get(c)) for r in records], dtype=np.float64).reshape(n))
        for p in params:
            root.create_array(f"parameter/{p}", data=np.array(
                [_as_float(r["swept"].get(p)) for r in records], dtype=np.float64).reshape(n))
        root.attrs["viform"] = {**context.describe(), "metrics": cols, "parameters": params,
                                "metric_units": {k: u for k, (_, u) in cmp.METRICS.items()},
                                "note": "one row per point; NaN: not defined for that sensor/scene, or "
                                        "that parameter is not swept for that sensor"}


def read_table(path) -> dict:
    """``sweep.zarr`` back as {column: array} (metric/* and parameter/* keep their prefixes).

    Parameters
    ----------
    path : str or Path
        The ``sweep.zarr`` store.

    Returns
    -------
    dict
        Column name → array, one row per point (``sensor``, ``point``, ``parameter/*``, ``metric/*``).
    """
    import zarr

    root = zarr.open_group(str(path), mode="r")
    out = {k: root[k][:] for k in ("sensor", "point_id", "label", "default")}
    for group in ("metric", "parameter"):
        if group in root:
            for k in root[group].array_keys():
                out[f"{group}/{k}"] = root[group][k][:]
    out["attrs"] = dict(root.attrs)
    return out


def _as_float(v) -> float:
    if v is None or isinstance(v, (dict, list, str)):
        return math.nan
    return float(v)


class ContextMismatch(ViformError):
    """A folder holds a sweep made in another context: ``field`` of it differs (``stored`` there, ``wanted`` now)."""

    def __init__(self, out, field: str, stored, wanted, name: str = "out"):
        self.out, self.field, self.stored, self.wanted = str(out), field, stored, wanted
        super().__init__(f"{name} = {self.out!r} holds a sweep made with other settings ({field}: {stored!r} there, "
                         f"{wanted!r} now); give another folder, or the same settings to extend or resume it")

    def __reduce__(self):
        return type(self), (self.out, self.field, self.stored, self.wanted)


def check_context(out: Path, context) -> None:
    """Refuse a folder ``out`` that holds a sweep of another scene, size, duration, instants or seed
    (:class:`ContextMismatch`), or a ``sweep.json`` that is not a sweep's (it is never written over)."""
    path = Path(out) / "sweep.json"
    if not path.is_file():
        return
    try:
        doc = json.loads(path.read_text())
        why = None if isinstance(doc, dict) and isinstance(doc.get("context", {}), dict) else "not a sweep's record"
    except (OSError, ValueError) as exc:
        why = one_line(exc)
    if why is not None:
        raise ViformError(f"out = {str(out)!r} holds a sweep.json viform cannot read as a sweep ({why}); give "
                          "another folder, or move that file away") from None
    old = doc.get("context", {})
    new = context.describe()
    if old == json.loads(json.dumps(new)):
        return
    diff = next((k for k in new if old.get(k) != json.loads(json.dumps(new[k]))), "format")
    raise ContextMismatch(out, diff, old.get(diff), new.get(diff))
