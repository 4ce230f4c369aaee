"""MOTChallenge files: object truth (``gt.txt``), tracker results and ``seqinfo.ini``.

The multi-object tracking benchmarks (MOT15–MOT20; read by TrackEval, py-motmetrics and most
trackers) store one text line per object per frame. viform writes the same files so any MOT
evaluator scores a tracker against viform's exact truth:

* ``gt.txt``: ``frame, id, x, y, w, h, conf, class, visibility, detectability`` — boxes clipped
  to the image (what any camera can report; the part outside is counted in the visibility),
  ``conf`` 1 where any part of the object is visible and 0 where it is entirely hidden (such rows
  need not be found), ``class`` an integer (the names are listed in ``seqinfo.ini``),
  ``visibility`` the visible fraction of the whole object in [0, 1], and ``detectability`` the
  evidence the sensor's pixels hold about it (:mod:`viform.vision.detectability`: ≥ 1 the
  sensor shows it; −1 unknown). Evaluators that read nine columns ignore the tenth;
* results: ``frame, id, x, y, w, h, conf, -1, -1, -1``.

Frames count from 1: frame k is output step k (step k covers ticks [(k − 1)·N, k·N) of a
stream read every N ticks; its truth is taken at the end of the step, t = start + k·N/f, the
latest instant the step has seen). Boxes count pixels from 1 in the files, as the format
does; in memory (the arrays these functions take and return) they are 0-based, the
convention of :mod:`viform.light.truth`. ``seqinfo.ini`` records the step in ticks, the clock,
the frame rate and the image size. Every file is written atomically.
"""

from __future__ import annotations

import configparser
import math
from pathlib import Path

import numpy as np

from viform._io import atomic_open
from viform._validate import ViformError, check_int, check_positive

#: Columns of a ground-truth array (0-based x, y in memory).
GT_COLUMNS = ("frame", "id", "x", "y", "w", "h", "conf", "class", "visibility", "detectability")
#: Columns of a results array (0-based x, y in memory); the file adds three −1 columns.
RESULT_COLUMNS = ("frame", "id", "x", "y", "w", "h", "conf")


def step_times_s(n_steps: int, step_ticks: int, clock_hz: float, start_time_s: float = 0.0) -> np.ndarray:
    """Instants (s) of output steps 1 … ``n_steps``: the end of each step, start + k·N/f.

    Parameters
    ----------
    n_steps : int
        Number of output steps (frames).
    step_ticks : int
        Ticks per output step (N ≥ 1).
    clock_hz : float
        Readout clock f, Hz.
    start_time_s : float
        Start of tick 0, s.
    """
    n_steps = check_int("n_steps", n_steps, 0)
    step_ticks = check_int("step_ticks", step_ticks, 1)
    clock_hz = check_positive("clock_hz", clock_hz)
    return start_time_s + np.arange(1, n_steps + 1) * step_ticks / clock_hz


def class_ids_of(scene, times_s) -> dict[str, int]:
    """Class name → integer id (from 1, in order of first appearance by object id over ``times_s``)."""
    return _class_ids(_objects_by_id(scene, np.asarray(times_s, dtype=np.float64).ravel()))


def _objects_by_id(scene, times) -> list:
    """Each instant's objects, in object-id order."""
    return [sorted(scene.objects(float(t)), key=lambda o: o.object_id) for t in times]


def _class_ids(objects_by_instant) -> dict[str, int]:
    ids: dict[str, int] = {}
    for found in objects_by_instant:
        for obj in found:
            ids.setdefault(obj.class_name, len(ids) + 1)
    return ids


def gt_rows(scene, times_s, class_ids: dict[str, int] | None = None, *, detectability=None,
            start_time_s: float = 0.0, return_class_ids: bool = False):
    """Ground-truth rows from any scene's :meth:`~viform.light.scenes.Scene.objects`.

    Parameters
    ----------
    scene : Scene
        A scene that gives object truth (``"objects" in scene.truth_kinds()``); others raise
        :class:`~viform.light.truth.TruthUnavailable`.
    times_s : array_like
        Instant of each frame; frame k (from 1) is ``times_s[k − 1]`` (see :func:`step_times_s`).
    class_ids : dict, optional
        Class name → integer id (default :func:`class_ids_of`).
    detectability : callable, optional
        ``detectability(object, seen_s)`` → the sensor's evidence about the object
        (:class:`~viform.vision.detectability.SpikeDetectability` or ``FrameDetectability``);
        ``seen_s`` is the time since it came into view (since ``start_time_s`` for objects in
        view in frame 1; else since the frame before the first that shows it). None: −1 (unknown).
    start_time_s : float
        The start of the recording, s.
    return_class_ids : bool
        Also return the class ids used (for :func:`write_seqinfo`): each instant's objects are asked
        for once, not once more by :func:`class_ids_of`.

    Returns
    -------
    ndarray, shape (N, 10), float64
        Columns :data:`GT_COLUMNS`, x and y 0-based, boxes clipped to the image (what a camera can
        report; rows of objects wholly outside it are left out); ``conf`` is 1 where any part of
        the object is visible, 0 where it is entirely hidden; ``visibility`` the visible fraction
        of the whole object; ``detectability`` −1 where unknown. Sorted by frame, id.
    dict
        Class name → id, only with ``return_class_ids``.
    """
    times = np.asarray(times_s, dtype=np.float64).ravel()
    objects = _objects_by_id(scene, times)  # each instant's once (the default class ids come from them too)
    if class_ids is None:
        class_ids = _class_ids(objects)
    rows, since = [], {}
    for k, (t, found) in enumerate(zip(times, objects, strict=True), start=1):
        for obj in found:
            x0, y0, w, h = obj.box_xywh
            x1, y1 = min(x0 + w, scene.width), min(y0 + h, scene.height)
            x0, y0 = max(x0, 0.0), max(y0, 0.0)
            w, h = x1 - x0, y1 - y0
            if w <= 0 or h <= 0:
                continue
            if obj.class_name not in class_ids:
                raise ViformError(f"class {obj.class_name!r} of object {obj.object_id} has no id in class_ids")
            since.setdefault(obj.object_id, float(start_time_s) if k == 1 else float(times[k - 2]))
            d = -1.0
            if detectability is not None:
                d = float(detectability(obj, float(t) - since[obj.object_id]))
                d = -1.0 if math.isnan(d) else d
            rows.append((k, obj.object_id, x0, y0, w, h, 1.0 if obj.visible_fraction > 0 else 0.0,
                         class_ids[obj.class_name], obj.visible_fraction, d))
    rows = np.array(rows, dtype=np.float64).reshape(-1, len(GT_COLUMNS))
    return (rows, class_ids) if return_class_ids else rows


def _format(value: float, digits: int = 4) -> str:
    """A number as MOTChallenge files print it: integers bare, others to ``digits`` decimals, no trailing zeros."""
    text = f"{float(value):.{digits}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _check_rows(rows, columns, what) -> np.ndarray:
    rows = np.asarray(rows, dtype=np.float64)
    if rows.size == 0:
        return rows.reshape(0, len(columns))
    if rows.ndim == 2 and columns is GT_COLUMNS and rows.shape[1] == len(columns) - 1:
        rows = np.column_stack([rows, np.full(len(rows), -1.0)])  # nine MOTChallenge columns: unknown
    if rows.ndim != 2 or rows.shape[1] != len(columns):
        raise ViformError(f"{what} rows must have shape (N, {len(columns)}): {', '.join(columns)}; got {rows.shape}")
    if not np.all(np.isfinite(rows)):
        raise ViformError(f"{what} rows hold NaN or infinite values")
    if rows[:, 0].min() < 1 or not np.all(rows[:, 0] == np.round(rows[:, 0])):
        raise ViformError(f"{what} frames must be whole numbers ≥ 1 (MOTChallenge counts frames from 1)")
    return rows


def write_gt(path, rows) -> Path:
    """Write ground-truth rows (:data:`GT_COLUMNS`, 0-based x, y) as a MOTChallenge ``gt.txt``."""
    rows = _check_rows(rows, GT_COLUMNS, "ground-truth")
    lines = []
    for r in rows:
        fields = [int(r[0]), int(r[1]), r[2] + 1, r[3] + 1, r[4], r[5], int(r[6]), int(r[7]), r[8]]
        detect = "-1" if r[9] < 0 else _format(r[9], 3)
        lines.append(",".join(_format(v) for v in fields) + "," + detect)
    with atomic_open(path, "w") as f:
        f.write("".join(line + "\n" for line in lines))
    return Path(path)


def write_results(path, rows) -> Path:
    """Write tracker results (:data:`RESULT_COLUMNS`, 0-based x, y) as ``frame,id,x,y,w,h,conf,-1,-1,-1``."""
    rows = _check_rows(rows, RESULT_COLUMNS, "result")
    lines = []
    for r in rows:
        fields = [int(r[0]), int(r[1]), r[2] + 1, r[3] + 1, r[4], r[5], r[6]]
        lines.append(",".join(_format(v) for v in fields) + ",-1,-1,-1")
    with atomic_open(path, "w") as f:
        f.write("".join(line + "\n" for line in lines))
    return Path(path)


def _read(path, n_columns: int, what: str, keep: int | None = None) -> np.ndarray:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ViformError(f"{what} file {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split(",")]
        except ValueError:
            raise ViformError(f"{what} file {str(path)!r} line {number} is not comma-separated numbers") from None
        if len(values) < n_columns:
            raise ViformError(f"{what} file {str(path)!r} line {number} has {len(values)} values; "
                              f"MOTChallenge {what} lines have at least {n_columns}")
        if keep is not None:  # optional trailing columns: −1 where absent
            values = (values + [-1.0] * keep)[:keep]
        rows.append(values[: keep or n_columns])
    rows = np.array(rows, dtype=np.float64).reshape(-1, keep or n_columns)
    if rows.size and (not np.all(np.isfinite(rows)) or rows[:, 0].min() < 1):
        raise ViformError(f"{what} file {str(path)!r} holds a frame < 1 or a value that is not finite")
    rows[:, 2:4] -= 1.0  # back to 0-based pixels
    return rows


def read_gt(path) -> np.ndarray:
    """Read a MOTChallenge ``gt.txt``: (N, 10) rows of :data:`GT_COLUMNS`, x and y 0-based.

    Files with the nine standard columns (other tools) read with detectability −1 (unknown).
    """
    return _read(path, len(GT_COLUMNS) - 1, "ground-truth", len(GT_COLUMNS))


def read_results(path) -> np.ndarray:
    """Read MOTChallenge results: (N, 7) rows of :data:`RESULT_COLUMNS`, x and y 0-based."""
    return _read(path, len(RESULT_COLUMNS), "results")


def write_seqinfo(path, *, name: str, n_frames: int, step_ticks: int, clock_hz: float, width: int, height: int,
                  start_time_s: float = 0.0, classes: dict[str, int] | None = None) -> Path:
    """Write a MOTChallenge ``seqinfo.ini`` with viform's timing keys.

    The standard keys (``name``, ``frameRate``, ``seqLength``, ``imWidth``, ``imHeight``) are
    followed by ``frameStepTicks`` (N), ``clockHz`` (f, Hz), ``startTimeS`` and ``classes``
    (names in class-id order), so frame k is the instant ``startTimeS + k·N/f``.
    """
    step_ticks = check_int("step_ticks", step_ticks, 1)
    clock_hz = check_positive("clock_hz", clock_hz)
    config = configparser.ConfigParser()
    config.optionxform = str  # keep the format's camelCase keys
    names = [n for n, _ in sorted((classes or {}).items(), key=lambda item: item[1])]
    config["Sequence"] = {
        "name": str(name), "imDir": "img1", "frameRate": repr(clock_hz / step_ticks),
        "seqLength": str(check_int("n_frames", n_frames, 0)), "imWidth": str(check_int("width", width, 1)),
        "imHeight": str(check_int("height", height, 1)), "imExt": ".png",
        "frameStepTicks": str(step_ticks), "clockHz": repr(float(clock_hz)), "startTimeS": repr(float(start_time_s)),
        "classes": ",".join(names),
    }
    with atomic_open(path, "w") as f:
        config.write(f)
    return Path(path)


def read_seqinfo(path) -> dict:
    """Read ``seqinfo.ini``: a dict with ``name``, ``frame_rate_hz``, ``n_frames``, ``width``, ``height``,
    ``step_ticks``, ``clock_hz``, ``start_time_s`` and ``classes`` (name → id); the last four are
    None / {} in files written by other tools."""
    config = configparser.ConfigParser()
    config.optionxform = str
    try:
        if not config.read(path):
            raise ViformError(f"seqinfo file {str(path)!r} cannot be read")
        seq = config["Sequence"]
        info = {"name": seq.get("name", ""), "frame_rate_hz": float(seq["frameRate"]),
                "n_frames": int(seq["seqLength"]), "width": int(seq["imWidth"]), "height": int(seq["imHeight"]),
                "step_ticks": int(seq["frameStepTicks"]) if "frameStepTicks" in seq else None,
                "clock_hz": float(seq["clockHz"]) if "clockHz" in seq else None,
                "start_time_s": float(seq.get("startTimeS", "0"))}
        names = [n for n in seq.get("classes", "").split(",") if n]
    except (KeyError, ValueError, configparser.Error) as exc:
        raise ViformError(f"seqinfo file {str(path)!r} is not a MOTChallenge seqinfo.ini: {exc}") from None
    info["classes"] = {n: i for i, n in enumerate(names, start=1)}
    if info["clock_hz"] is not None and not math.isfinite(info["clock_hz"]):
        raise ViformError(f"seqinfo file {str(path)!r}: clockHz must be finite")
    return info
