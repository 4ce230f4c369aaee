"""Running a sweep: one point shot and scored as ``viform compare`` does it, the points on dask
workers or in this process, the results stored as they finish."""

from __future__ import annotations

import json
import math
import os
import threading
import time
import uuid
from pathlib import Path

import numpy as np

from viform._io import write_json
from viform._parallel import (
    DEFAULT_CONNECT_TIMEOUT_S,
    SchedulerLost,
    check_connect_timeout,
    completed,
    one_line_warnings,
    open_client,
    parse_memory,
)
from viform._validate import ViformError, check_int, one_line
from viform.measure import comparison as cmp
from viform.measure.sweep.answer import answer
from viform.measure.sweep.parameters import make_point_sensor
from viform.measure.sweep.plan import Point, SweepContext, SweepPlan, point_seed
from viform.measure.sweep.store import (
    POINTS_DIR,
    _finite,
    _restore,
    check_context,
    load_point,
    store_point,
    write_table,
)
from viform.sensors.spike_cuda import DEVICES  # noqa: F401 -- a sweep's devices are every simulation's

#: Contrast-to-noise at which a target counts as seen (as compare's verdict counts it).
SEEN_CNR = 3.0


def _close_all(parts) -> None:
    """Close a sweep's own client and cluster, in this order (every one, even when one fails)."""
    try:
        for part in parts[:-1]:
            part.close()
    finally:
        if parts:
            parts[-1].close()


class _Closing(threading.Thread):
    """A thread that closes a sweep's own client and cluster; ``join()`` raises what closing them raised."""

    def __init__(self, parts):
        super().__init__(name="viform-sweep-close", daemon=True)
        self.parts, self.error = parts, None

    def run(self):
        try:
            _close_all(self.parts)
        except BaseException as exc:  # noqa: BLE001 -- raised by join() in the caller's thread
            self.error = exc

    def join(self, timeout=None):
        super().join(timeout)
        if self.error is not None:
            error, self.error = self.error, None
            raise error


def join_closing(closing: list, failed: bool) -> None:
    """Wait for every :class:`_Closing` thread of ``closing``; what closing raised is raised only when the
    caller has not ``failed`` (its own error, not the cluster's shut-down, is the one the user sees)."""
    errors = []
    for thread in closing:
        try:
            thread.join()
        except BaseException as exc:  # noqa: BLE001 -- raised below, once every thread is joined
            errors.append(exc)
    if errors and not failed:
        raise errors[0]


def run_point(context: SweepContext, point: Point, scene=None, device: str = "cpu") -> dict:
    """Shoot and score one point (runs on a worker); returns its record and its images.

    The record holds the metrics of :func:`viform.measure.comparison.score`; ``images`` holds the
    light estimate (lux, float32; NaN where under-exposed) at each instant, for the report.
    ``scene`` is the point's scene when the caller has made it already (points of one task share
    it); ``device`` runs a spike sensor's simulation there ("cpu" or "cuda"; others run on the CPU).
    """
    from numba import get_num_threads, set_num_threads

    # CPU of the whole process (numba may run a kernel on its own pool thread): one point at a time per
    # worker process, so this is the point's CPU time (an overestimate when threads share a process)
    started, cpu = time.perf_counter(), time.process_time()
    threads = get_num_threads()
    set_num_threads(1)  # one point per worker: parallelism comes from the workers
    try:
        scene = context.make_scene(point.scene) if scene is None else scene
        sensor = make_point_sensor(point.sensor, dict(point.settings))
        seed = point_seed(context.seed, point)
        spike = cmp.compare_entry(point.sensor).family == "spike"
        methods = [context.spike_image] if spike else None
        try:
            shots = cmp.shoot(point.sensor, scene, context.duration_s, list(context.instants_s), seed=seed,
                              sensor=sensor, spike_methods=methods, device=device)
        except (ViformError, ValueError) as exc:  # this setting cannot shoot this scene (light beyond its range …)
            why = one_line(exc) if isinstance(exc, ViformError) else f"the model refused this light ({one_line(exc)})"
            shots = [cmp.Shot(point.sensor, point.label(), "", skipped=why)]
        shot = shots[0]
        shot.metrics = cmp.score(shot, scene, list(context.instants_s))
    finally:
        set_num_threads(threads)
    metrics = {k: (float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v)
               for k, v in shot.metrics.items()}
    if isinstance(metrics.get("target_cnr"), dict):  # scenes with targets (night-road-fog): how many are seen
        metrics["targets_seen"] = float(sum(v >= SEEN_CNR for v in metrics["target_cnr"].values()))
    if context.tracking and not shot.skipped:
        metrics.update(tracking_scores(scene, context.duration_s, shot))
    warning = spike_support_warning(shot.raw, context.spike_image) if spike and not shot.skipped else None
    images = None
    if not shot.skipped:
        images = np.stack([np.where(e.underexposed, np.nan, np.nan_to_num(np.asarray(e.lux, np.float64)))
                           for e in shot.estimates]).astype(np.float32)
    record = {"point_id": point.point_id, "sensor": point.sensor, "settings": dict(point.settings),
              "swept": dict(point.swept), "default": point.is_default, "label": point.label(),
              "shot_label": shot.label, "skipped": shot.skipped, "seed": seed, "metrics": metrics,
              "context_sha256": context.fingerprint(),
              "seconds": time.perf_counter() - started, "cpu_seconds": time.process_time() - cpu}
    if point.scene:
        record["scene"] = dict(point.scene)
    if device != "cpu" and spike:
        record["device"] = device
    if warning:
        record["warning"] = warning
    return {"record": record, "images": images}


def spike_support_warning(stream, spike_image: str) -> str | None:
    """One line when a spike point's stream is too sparse for the images it is scored on
    (:func:`viform.imaging.support.spike_support`), else None."""
    from viform.imaging.support import imaging_need, spike_support

    if stream is None or not hasattr(stream, "read_ticks"):
        return None
    method = {"best": "multi-interval"}.get(spike_image, spike_image)
    window, need = imaging_need(method, stream.n_ticks, max(1, round(cmp.ACCUMULATION_WINDOW_S * stream.clock_hz)))
    return spike_support(stream, window, need).warning(f"its {spike_image} images",
                                                        "more light or a lower threshold would help")


def run_points(context: SweepContext, points, device: str = "cpu") -> list[dict]:
    """Shoot and score several points in one task, in order (:func:`run_point` each); points on the same
    scene setting share one scene object (its light caches included)."""
    scenes: dict = {}
    out = []
    for p in points:
        if p.scene not in scenes:
            scenes[p.scene] = context.make_scene(p.scene)
        out.append(run_point(context, p, scenes[p.scene], device))
    return out


def tracking_scores(scene, duration_s: float, shot) -> dict:
    """HOTA, MOTA, IDF1, ID switches, median latency and objects never found of the comparison's tracker
    on this shot (:func:`viform.measure.vision_comparison.vision_scores`); {} without object truth.

    Frame cameras' frames are turned into lux with the comparison's inverse response of the sensor at
    its default pixel parameters (exposure and frame times are the shot's own).
    """
    kinds = scene.truth_kinds() if hasattr(scene, "truth_kinds") else ()
    if "objects" not in kinds or shot.family == "gated":
        return {}
    from viform.measure.vision_comparison import vision_scores, vision_table

    rows = [r for r in vision_table(vision_scores({"scene": scene, "duration_s": duration_s, "shots": [shot]}))
            if "skipped" not in r]
    if not rows:
        return {}
    r = rows[0]
    lat = r["median_latency_ms"]
    return {"tracking_hota": float(r["hota"]), "tracking_mota": float(r["mota"]), "tracking_idf1": float(r["idf1"]),
            "tracking_id_switches": float(r["id_switches"]),
            "tracking_latency_s": math.nan if lat is None else lat / 1e3,
            "tracking_objects_missed": float(len(r["never_found"]))}


#: The modules a point's task imports (this one imports them all), imported once by the fork server a
#: local cluster's workers are forked from (:data:`viform._parallel.WORKER_START`), not again by each worker.
WORKER_MODULES = ("viform.measure.sweep.run",)


def _open(workers, scheduler, memory_limit, connect_timeout_s=DEFAULT_CONNECT_TIMEOUT_S):
    return open_client(workers, scheduler, parse_memory(memory_limit, "memory_limit"), connect_timeout_s,
                       preload=WORKER_MODULES)


#: Each task takes this fraction of the points not yet dealt, per worker (guided self-scheduling): the
#: first tasks hold several points (fewer tasks to schedule and transfer), the last ones one point each,
#: so no worker waits long for another at the end.
GUIDED_SHARE = 0.5


def batches(points, n_workers: int, share: float | None = None) -> list[list]:
    """``points`` dealt into tasks that shrink toward the end: each takes ``ceil(share × left /
    n_workers)`` of the points left (at least one; default :data:`GUIDED_SHARE`), the points first
    put in a strided order (every k-th point, k the number of tasks a full sweep of equal shares
    would have) so that a task holds a mix of the plan's settings. Results do not depend on the grouping."""
    share = GUIDED_SHARE if share is None else share
    n_workers = max(1, n_workers)
    sizes, left = [], len(points)
    while left:
        sizes.append(min(left, max(1, math.ceil(share * left / n_workers))))
        left -= sizes[-1]
    k = max(1, len(sizes))
    order = [p for r in range(k) for p in points[r::k]]
    out, at = [], 0
    for n in sizes:
        out.append(order[at:at + n])
        at += n
    return out


def check_device(device: str, sensors, name: str = "device") -> str:
    """The device a sweep of ``sensors`` runs its spike simulations on: ``device`` is "cpu", "cuda" or
    "auto" (a GPU when there is one), as for every simulation
    (:func:`viform.sensors.spike_cuda.resolve_device`, its messages); "cuda" needs a spike sensor.
    Returns "cpu" or "cuda"."""
    from viform.sensors.spike_cuda import resolve_device

    spike = any(cmp.compare_entry(k).family == "spike" for k in sensors)
    if device == "cuda" and not spike:
        raise ViformError(f"{name} = 'cuda' runs the spike camera's simulation on a GPU; this sweep has no spike "
                          f"sensor ({', '.join(sensors)})")
    device = resolve_device(device, name)
    return device if spike else "cpu"


def _start_while_shooting(start, todo, here, computed, out):
    """Start a local cluster (``start()`` → (client, cluster)) in a thread while this process shoots points
    (``here(point)``): first one point of each sensor, so that the kernels they need are compiled and in
    numba's disk cache before a worker loads them (the workers never compile what this process has), then
    further points until the cluster is up. Returns (client, cluster, the points left for the workers).

    The cluster's start is mostly waiting and the other processes' start-up, so this process's points are
    work done in time that was idle; a cluster that cannot start stops the run with one line saying how
    many points are stored."""
    import threading

    box: dict = {}

    def open_cluster():
        try:
            box["opened"] = start()
        except BaseException as exc:  # noqa: BLE001 -- raised in the caller's thread below
            box["error"] = exc

    thread = threading.Thread(target=open_cluster, name="viform-sweep-cluster", daemon=True)
    thread.start()
    first = {}
    for p in todo:
        first.setdefault(p.sensor, p)
    warm = list(first.values())
    queue = warm + [p for p in todo if p not in warm]
    done = 0
    try:
        while done < len(queue) and (done < len(warm) or thread.is_alive()):
            here(queue[done])
            done += 1
    except BaseException:
        thread.join()
        for part in box.get("opened", ()):  # the cluster that started meanwhile goes too
            part.close()
        raise
    thread.join()
    if "error" in box:
        exc = box["error"]
        if computed() and isinstance(exc, ViformError):
            raise ViformError(f"{one_line(exc).split('; nothing was written')[0]}; {computed()} points are stored, "
                              f"each whole, in {str(Path(out) / POINTS_DIR)!r}: run the same sweep again to "
                              "compute the others") from None
        raise exc
    client, cluster = box["opened"]
    return client, cluster, queue[done:]


def run_sweep(context: SweepContext, points, out, *, workers: int | None = None, scheduler: str | None = None,
              client=None, memory_limit="auto", progress: bool = True, crash_after_points: int | None = None,
              device: str = "cpu", connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S, on_connect=None,
              close_later: list | None = None) -> dict:
    """Run every point not already stored in ``out``; return the records (plan order) and run figures.

    ``workers=0`` runs the points in this process, one after the other (no dask); otherwise on a
    dask LocalCluster of ``workers`` processes (default: the CPU count), on ``scheduler``, or on
    an open ``client``, several points per task (:func:`batches`). A LocalCluster of the sweep's own
    starts while this process shoots the first points (one per sensor, then more until the cluster is
    up: :func:`_start_while_shooting`), so the workers find the kernels compiled. Each point is
    stored as soon as it is done; ``computed_here`` counts those shot in this process.
    ``crash_after_points`` (testing aid) ends this process abruptly after storing that many new
    points, as a kill would.

    Faults: points are computed on the workers and stored here, each whole (images, then the
    record that marks it finished); a worker that dies has its task computed again by dask. A
    lost scheduler (or one without a worker for ``connect_timeout_s``) stops the run with one
    line saying how many points are stored; running the same sweep again computes only the others.
    ``on_connect(scheduler, connect_timeout_s)`` is called just before a ``scheduler`` is reached.
    The run figures include ``timings``, where the wall time went, in seconds from the start:
    ``cluster_up_s`` (a local cluster of the sweep's own is up), ``first_task_s`` (the first task's
    results are back), ``points_s`` (every point stored), ``closed_s`` (the client and cluster
    closed, or handed to ``close_later``); and ``store_s``, the time spent storing points in this process.

    ``close_later`` (a list): a local cluster of the sweep's own, once every point is stored, is closed
    in a thread appended to it, which the caller joins after writing the results (closing the workers
    takes 0.5–1.2 s of waiting, measured); without it, or after a failure, it is closed before returning.
    """
    out = Path(out)
    stored = {p.point_id: load_point(out, p, context) for p in points}
    todo = [p for p in points if stored[p.point_id] is None]
    records = {pid: r for pid, r in stored.items() if r is not None}
    started = time.perf_counter()
    computed = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(points), initial=len(records), unit="point", desc="sweep", leave=False)

    timings = {"store_s": 0.0}  # where the wall time goes (see run_sweep's return)

    def take(result):
        nonlocal computed
        t0 = time.perf_counter()
        store_point(out, result)
        rec = _restore(json.loads(json.dumps(_finite(result["record"]))))
        records[rec["point_id"]] = rec
        computed += 1
        timings["store_s"] += time.perf_counter() - t0
        if bar is not None:
            bar.update(1)
        if crash_after_points is not None and computed >= crash_after_points:
            os._exit(70)

    n_workers = here_count = 0
    own_client = own_cluster = None
    finished = False
    scenes: dict = {}

    def here(p):  # a point shot and stored in this process (its scene made once per setting)
        if p.scene not in scenes:
            scenes[p.scene] = context.make_scene(p.scene)
        take(run_point(context, p, scenes[p.scene], device))

    if todo and client is None and workers != 0 and scheduler is not None:  # unreachable: nothing written yet
        if on_connect is not None:
            on_connect(scheduler, connect_timeout_s)
        own_client, own_cluster = _open(workers or 1, scheduler, memory_limit, connect_timeout_s)
        client = own_client
    (out / POINTS_DIR).mkdir(parents=True, exist_ok=True)
    try:
        if todo and client is None and workers == 0:
            for p in todo:
                here(p)
            here_count = computed
        elif todo and client is None:  # a local cluster of our own
            n = max(1, min(os.cpu_count() or 1, len(todo))) if workers is None else workers
            own_client, own_cluster, todo_left = _start_while_shooting(
                lambda: _open(n, None, memory_limit, connect_timeout_s), todo, here, lambda: computed, out)
            client = own_client
            here_count = computed
            timings["cluster_up_s"] = time.perf_counter() - started
            n_workers = len(client.scheduler_info().get("workers", {}))
        else:
            todo_left = todo
        if todo and client is not None and todo_left:
            n_workers = len(client.scheduler_info().get("workers", {}))
            token = uuid.uuid4().hex[:8]
            futures = [client.submit(one_line_warnings(run_points), context, batch, device, pure=False,
                                     key=f"viform-sweep-{batch[0].point_id}-{len(batch)}-{token}")
                       for batch in batches(todo_left, n_workers)]
            try:
                for _, results in completed(client, futures, connect_timeout_s):
                    if isinstance(results, BaseException):
                        raise results
                    timings.setdefault("first_task_s", time.perf_counter() - started)
                    for result in results:  # a task's points, each stored whole
                        take(result)
            except SchedulerLost as exc:
                raise ViformError(f"{exc}: {len(records)} of {len(points)} points are stored, each whole, in "
                                  f"{str(out / POINTS_DIR)!r}; run the same sweep again to compute the other "
                                  f"{len(points) - len(records)}") from None
        timings["points_s"] = time.perf_counter() - started
        finished = True
    finally:
        if bar is not None:
            bar.close()
        parts = [part for part in (own_client, own_cluster) if part is not None]
        if parts and finished and close_later is not None:  # closed while the caller writes the results
            closing = _Closing(parts)
            closing.start()
            close_later.append(closing)
        else:
            _close_all(parts)
    timings["closed_s"] = time.perf_counter() - started
    ordered = [records[p.point_id] for p in points]
    new = [r for r in ordered if r["point_id"] in {p.point_id for p in todo}]
    return {"records": ordered, "computed": computed, "computed_here": here_count, "reused": len(points) - computed,
            "seconds": time.perf_counter() - started, "workers": n_workers,
            "cpu_seconds": sum(r.get("cpu_seconds", 0.0) for r in new), "timings": timings}


def sweep(plan: SweepPlan, out, *, workers: int | None = None, scheduler: str | None = None, client=None,
          memory_limit="auto", progress: bool = True, crash_after_points: int | None = None,
          device: str = "cpu", connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S, on_connect=None,
          close_later: list | None = None) -> dict:
    """Run a planned sweep into ``out``: points, ``sweep.zarr`` and ``sweep.json``; returns the sweep document.

    ``device`` ("cpu" or "cuda") runs the spike sensor's simulations there; it is recorded with each
    spike point and in ``sweep.json``, and is not part of the context (a sweep started on a GPU may be
    resumed on a CPU: the two give the same bits except in rare last-bit roundings, see
    :mod:`viform.sensors.spike_cuda`). ``connect_timeout_s`` bounds the wait for ``scheduler`` (at the
    start and after losing it; see :func:`run_sweep` for the faults), and ``on_connect`` is called
    just before it is reached. A local cluster of the sweep's own is closed while the table and
    ``sweep.json`` are written (joined before returning), or, with ``close_later`` (a list), in a thread
    appended to it for the caller to join (:func:`run_sweep`).
    """
    from viform._io import check_output_folder

    out = Path(out)
    check_output_folder("out", out)
    if out.exists() and not out.is_dir():
        raise ViformError(f"out = {str(out)!r} is a file, not a folder")
    if scheduler is not None and workers is not None:
        raise ViformError(f"scheduler = {scheduler!r} excludes workers = {workers!r}: a scheduler brings its own "
                          "workers")
    if workers is not None:
        workers = check_int("workers", workers, 0, 1024)
    memory_limit = parse_memory(memory_limit, "memory_limit")
    connect_timeout_s = check_connect_timeout(connect_timeout_s)
    device = check_device(device, plan.sensors)
    check_context(out, plan.context)
    closing = [] if close_later is None else close_later
    failed = True
    try:
        run = run_sweep(plan.context, plan.points, out, workers=workers, scheduler=scheduler, client=client,
                        memory_limit=memory_limit, progress=progress, crash_after_points=crash_after_points,
                        device=device, connect_timeout_s=connect_timeout_s, on_connect=on_connect,
                        close_later=closing)
        doc = _write_results(plan, out, run, device)
        failed = False
        return doc
    finally:
        if close_later is None:
            join_closing(closing, failed)


def _write_results(plan: SweepPlan, out: Path, run: dict, device: str) -> dict:
    """Write a run's ``sweep.zarr`` and ``sweep.json``; return the sweep document."""
    records = run["records"]
    result = answer(records, plan.demands, plan.objective)
    write_table(out / "sweep.zarr", records, plan.context)
    doc = {"context": plan.context.describe(), "sensors": plan.sensors,
           "vary": {k: v for k, v in plan.vary.items() if v}, "n_points": len(records),
           "computed": run["computed"], "reused": run["reused"], "seconds": run["seconds"],
           "cpu_seconds": run["cpu_seconds"], "workers": run["workers"], "computed_here": run["computed_here"],
           "device": device, "answer": result,
           "pareto": [list(p) for p in plan.pareto], "points": [_finite(r) for r in records]}
    write_json(out / "sweep.json", _finite(doc))
    doc["records"] = records
    doc["timings"] = run["timings"]
    return doc
