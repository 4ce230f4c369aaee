"""Tracking scores against exact truth: the field's metrics (TrackEval), latency and position error.

HOTA with its detection and association parts DetA and AssA (Luiten et al., IJCV 2021), MOTA
and ID switches (CLEAR MOT, Bernardin & Stiefelhagen 2008) and IDF1 (Ristani et al. 2016) come
from TrackEval, the MOTChallenge's own evaluation code; viform only hands it the per-frame ids
and IoU matrices, as its MOTChallenge reader would.

Rows that need not be found are marked, not dropped (MOTChallenge's treatment of its distractor
rows): a reported box that matches one (IoU ≥ 0.5, one-to-one by the Hungarian method over all
the frame's rows) is neither a hit nor a false positive, and an unmatched one is not a miss.
Scores *over all objects* excuse the rows of objects entirely hidden (``conf`` 0: a tracker that
keeps a hidden object where it is is not wrong, nor one that drops it); scores *over the
detectable objects* also excuse the rows whose detectability is under 1 (the sensor's pixels do
not show the object there: :mod:`viform.vision.detectability`).

What those libraries lack and this project is about (seed 000: "a thousand times faster than
the human eye"):

* **latency** per object: time from its appearance (start of the stream, or the instant it
  entered the field) to the first reported box that overlaps it (IoU ≥ 0.1, "found") and to
  the first that matches it at IoU ≥ 0.5 (the MOT match threshold), in seconds and ticks;
* **position error** per object: median distance between the centres of the matched box and
  the true box, px, beside the object's speed (px/s).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from viform._validate import ViformError
from viform.vision.detectability import DETECTABLE
from viform.vision.tracking import iou_matrix

#: IoU at which a reported box counts as *found* for latency (overlap, not yet accurate).
FOUND_IOU = 0.1
#: IoU of a match (MOTA, IDF1, position error, "never found").
MATCH_IOU = 0.5


def _by_frame(rows, n_frames):
    frames = [np.zeros((0, rows.shape[1]))] * n_frames
    if rows.size:
        order = np.argsort(rows[:, 0], kind="stable")
        rows = rows[order]
        keys, starts = np.unique(rows[:, 0].astype(np.int64), return_index=True)
        for key, part in zip(keys, np.split(rows, starts[1:]), strict=True):
            if 1 <= key <= n_frames:
                frames[key - 1] = part
    return frames


def _as_gt(gt_rows) -> np.ndarray:
    """(N, 10) ground-truth rows; nine-column rows get detectability −1 (unknown)."""
    gt = np.asarray(gt_rows, np.float64)
    if gt.size == 0:
        return np.zeros((0, 10))
    gt = gt.reshape(-1, gt.shape[-1])
    if gt.shape[1] == 9:
        gt = np.column_stack([gt, np.full(len(gt), -1.0)])
    if gt.shape[1] != 10:
        raise ViformError(f"ground-truth rows must have 9 or 10 columns; got {gt.shape[1]}")
    return gt


def excused(gt_rows, detectable_only: bool = False) -> np.ndarray:
    """Rows that need not be found: objects entirely hidden, and (``detectable_only``) those under detectability 1."""
    gt = _as_gt(gt_rows)
    out = gt[:, 6] <= 0
    if detectable_only:
        out |= (gt[:, 9] >= 0) & (gt[:, 9] < DETECTABLE)
    return out


def _drop_excused(gt, res, n_frames, skip):
    """Remove the excused rows, and the reported boxes that match them (IoU ≥ 0.5, one-to-one per frame)."""
    if not skip.any():
        return gt, res
    keep_res = np.ones(len(res), bool)
    if len(res):
        gframes = _by_frame(np.column_stack([gt, skip, np.arange(len(gt))]), n_frames)
        order = np.arange(len(res))
        rframes = _by_frame(np.column_stack([res, order]), n_frames)
        for g, r in zip(gframes, rframes, strict=True):
            if not len(g) or not len(r) or not g[:, -2].any():
                continue
            iou = iou_matrix(g[:, 2:6], r[:, 2:6])
            iou[iou < MATCH_IOU - 1e-12] = 0.0
            rows, cols = linear_sum_assignment(-iou)
            for i, j in zip(rows, cols, strict=True):
                if iou[i, j] > 0 and g[i, -2]:
                    keep_res[int(r[j, -1])] = False
    return gt[~skip], res[keep_res]


def trackeval_scores(gt_rows, result_rows, n_frames: int, detectable_only: bool = False) -> dict:
    """HOTA, DetA, AssA, MOTA, MOTP, IDF1 and ID switches from TrackEval.

    Parameters
    ----------
    gt_rows : ndarray (N, 10) or (N, 9)
        Ground truth (:data:`viform.vision.motchallenge.GT_COLUMNS`); rows that need not be found
        (:func:`excused`) are neither hits nor misses, and boxes matching them are not false positives.
    result_rows : ndarray (M, ≥ 7)
        Tracker output (frame, id, x, y, w, h, conf, …).
    n_frames : int
        Frames of the sequence (frames 1 … n_frames are scored, empty ones included).
    detectable_only : bool
        Score over the detectable objects (also excuse rows under detectability 1).

    Returns
    -------
    dict
        ``hota``, ``deta``, ``assa`` (mean over TrackEval's IoU thresholds 0.05 … 0.95), ``mota``,
        ``motp``, ``idf1``, ``id_switches``, ``true_positives``, ``false_positives``,
        ``false_negatives``, ``gt_boxes``, ``result_boxes``.
    """
    try:
        from trackeval.metrics import CLEAR, HOTA, Identity
    except ImportError:
        raise ViformError("scoring needs TrackEval: pip install 'viform[vision]' (or pip install trackeval)") from None
    gt = _as_gt(gt_rows)
    res = np.asarray(result_rows, np.float64)
    res = res.reshape(-1, res.shape[-1] if res.ndim == 2 and res.size else 7)
    gt, res = _drop_excused(gt, res, n_frames, excused(gt, detectable_only))
    gt_ids = {v: i for i, v in enumerate(np.unique(gt[:, 1]))}
    tr_ids = {v: i for i, v in enumerate(np.unique(res[:, 1]))} if res.size else {}
    data = {"num_timesteps": n_frames, "num_gt_ids": len(gt_ids), "num_tracker_ids": len(tr_ids),
            "num_gt_dets": int(len(gt)), "num_tracker_dets": int(len(res)),
            "gt_ids": [], "tracker_ids": [], "similarity_scores": []}
    for g, r in zip(_by_frame(gt, n_frames), _by_frame(res, n_frames), strict=True):
        data["gt_ids"].append(np.array([gt_ids[v] for v in g[:, 1]], int))
        data["tracker_ids"].append(np.array([tr_ids[v] for v in r[:, 1]], int))
        data["similarity_scores"].append(iou_matrix(g[:, 2:6], r[:, 2:6]))
    quiet = {"PRINT_CONFIG": False}
    hota = HOTA().eval_sequence(data)
    clear = CLEAR(quiet).eval_sequence(data)
    ident = Identity(quiet).eval_sequence(data)
    return {"hota": float(np.mean(hota["HOTA"])), "deta": float(np.mean(hota["DetA"])),
            "assa": float(np.mean(hota["AssA"])), "mota": float(clear["MOTA"]), "motp": float(clear["MOTP"]),
            "idf1": float(ident["IDF1"]), "id_switches": int(clear["IDSW"]), "true_positives": int(clear["CLR_TP"]),
            "false_positives": int(clear["CLR_FP"]), "false_negatives": int(clear["CLR_FN"]),
            "gt_boxes": int(len(gt)), "result_boxes": int(len(res))}


def _matches(g, r, threshold):
    if not len(g) or not len(r):
        return []
    iou = iou_matrix(g[:, 2:6], r[:, 2:6])
    rows, cols = linear_sum_assignment(-iou)
    return [(i, j, iou[i, j]) for i, j in zip(rows, cols, strict=True) if iou[i, j] >= threshold]


def _speed(rows, times) -> float:
    """An object's mean speed, px/s, from its truth boxes where they are whole (not cut by the border).

    A box clipped to the image moves its centre at a fraction of the object's speed, so only
    consecutive frames where the box has its full size count (all frames where it never has).
    """
    rows = rows[np.argsort(rows[:, 0])]
    if len(rows) < 2:
        return math.nan
    frames = rows[:, 0].astype(int)
    ok = (frames >= 1) & (frames <= len(times))
    rows, frames = rows[ok], frames[ok]
    if len(rows) < 2:
        return math.nan
    whole = (rows[:, 4] >= rows[:, 4].max() - 1e-6) & (rows[:, 5] >= rows[:, 5].max() - 1e-6)
    pairs = whole[1:] & whole[:-1] & (np.diff(frames) == 1)
    if not pairs.any():
        pairs = np.ones(len(rows) - 1, bool)
    centres = rows[:, 2:4] + rows[:, 4:6] / 2
    t = times[frames - 1]
    speed = np.hypot(*np.diff(centres, axis=0).T) / np.diff(t)
    return float(np.mean(speed[pairs]))


def object_latency_and_error(gt_rows, result_rows, times_s, clock_hz: float | None = None,
                             start_time_s: float = 0.0, detectable_only: bool = False) -> dict:
    """Per object: latency to found / matched, position error, speed.

    The appearance of an object is the start of the stream when it is visible in frame 1,
    else the instant of the frame before the first one that shows it (the true instant lies
    within that step, so the latency is exact to one output step); with ``detectable_only``,
    the first frame at which it is detectable counts as its appearance.

    Parameters
    ----------
    gt_rows, result_rows : ndarray
        As for :func:`trackeval_scores`.
    times_s : array_like
        Instant of each frame (frame k = ``times_s[k − 1]``), s.
    clock_hz : float, optional
        Spike clock: latencies are also given in ticks.

    Returns
    -------
    dict
        object id → ``{"appear_s", "latency_found_s", "latency_match_s", "latency_found_ticks",
        "latency_match_ticks", "position_error_px" (median over matched frames), "speed_px_per_s"
        (the object's own speed, from the scene's velocities where the truth carries them: else
        None), "matched_frames", "visible_frames"}``; latencies are None for an object never
        found / never matched.
    """
    times = np.asarray(times_s, np.float64).ravel()
    n = times.size
    every = _as_gt(gt_rows)
    gt = every[~excused(every, detectable_only)]
    res = np.asarray(result_rows, np.float64)
    res = res.reshape(-1, res.shape[-1]) if res.size else np.zeros((0, 7))
    gframes, rframes = _by_frame(gt, n), _by_frame(res, n)
    out = {}
    for oid in np.unique(gt[:, 1]):
        rows = gt[gt[:, 1] == oid]
        first = int(rows[:, 0].min())
        out[int(oid)] = {"appear_s": start_time_s if first == 1 else float(times[first - 2]),
                         "latency_found_s": None, "latency_match_s": None, "errors": [],
                         "speed_px_per_s": _speed(every[every[:, 1] == oid], times),
                         "visible_frames": int(len(rows))}
    for k in range(n):
        g, r = gframes[k], rframes[k]
        for i, j, iou in _matches(g, r, FOUND_IOU):
            entry = out[int(g[i, 1])]
            if entry["latency_found_s"] is None:
                entry["latency_found_s"] = float(times[k] - entry["appear_s"])
            if iou >= MATCH_IOU:
                if entry["latency_match_s"] is None:
                    entry["latency_match_s"] = float(times[k] - entry["appear_s"])
                dc = (g[i, 2:4] + g[i, 4:6] / 2) - (r[j, 2:4] + r[j, 4:6] / 2)
                entry["errors"].append(float(np.hypot(*dc)))
    for entry in out.values():
        errors = entry.pop("errors")
        entry["matched_frames"] = len(errors)
        entry["position_error_px"] = float(np.median(errors)) if errors else None
        for kind in ("found", "match"):
            s = entry[f"latency_{kind}_s"]
            entry[f"latency_{kind}_ticks"] = (None if s is None or clock_hz is None
                                              else int(round(s * clock_hz)))
    return out


def score_tracking(gt_rows, result_rows, times_s, clock_hz: float | None = None, start_time_s: float = 0.0) -> dict:
    """Everything: TrackEval's scores, per-object latency and error, and their summaries.

    Scored over all objects (rows of entirely hidden objects need not be found), and, where
    the truth carries detectability, over the detectable objects too (rows under 1 need not
    be found either).

    Parameters
    ----------
    gt_rows, result_rows : ndarray
        Ground truth and tracker output rows, as for :func:`trackeval_scores`.
    times_s : array_like
        Instant of each frame (frame k = ``times_s[k − 1]``), s.
    clock_hz : float, optional
        Spike clock, Hz: latencies are also given in ticks.
    start_time_s : float
        Start of the stream, s (an object visible in frame 1 appears then).

    Returns
    -------
    dict
        :func:`trackeval_scores` keys, plus ``objects`` (:func:`object_latency_and_error`),
        ``median_latency_found_s`` / ``_match_s`` (over the objects found), ``never_found``
        (ids of objects never matched at IoU ≥ 0.5), ``n_frames``, and ``detectable``: the
        same keys over the detectable objects, plus ``undetectable_rows`` and
        ``never_detectable`` (ids never detectable) — None when the truth has no detectability.
    """
    times = np.asarray(times_s, np.float64).ravel()
    gt = _as_gt(gt_rows)

    def summary(detectable_only):
        scores = trackeval_scores(gt, result_rows, times.size, detectable_only)
        objects = object_latency_and_error(gt, result_rows, times, clock_hz, start_time_s, detectable_only)
        for kind in ("found", "match"):
            values = [o[f"latency_{kind}_s"] for o in objects.values() if o[f"latency_{kind}_s"] is not None]
            scores[f"median_latency_{kind}_s"] = float(np.median(values)) if values else None
        scores["never_found"] = sorted(k for k, o in objects.items() if o["latency_match_s"] is None)
        scores["objects"] = objects
        scores["n_frames"] = int(times.size)
        return scores

    scores = summary(False)
    known = gt[:, 9] >= 0
    scores["detectable"] = None
    if known.any():
        detectable = summary(True)
        under = known & (gt[:, 6] > 0) & (gt[:, 9] < DETECTABLE)
        detectable["undetectable_rows"] = int(under.sum())
        seen = set(gt[(gt[:, 9] >= DETECTABLE) | ~known, 1].astype(int).tolist())
        detectable["never_detectable"] = sorted(set(gt[:, 1].astype(int).tolist()) - seen)
        scores["detectable"] = detectable
    return scores
