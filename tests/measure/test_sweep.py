"""``viform sweep``'s engine: value specs, demands, per-point seeds, worker-count independence, resuming."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from viform._validate import ViformError
from viform.measure import sweep as sw

#: A tiny sweep: dilemma at 48×32, a 12 ms clip (480 spike-camera ticks at 40 kHz).
TINY = dict(height=32, width=48, duration_s=0.012, instants_s=[0.004, 0.008], seed=3)


def tiny_plan(vary, sensors=None, require=None):
    return sw.make_plan("dilemma", sensors or list(dict.fromkeys(v.split(":")[0] for v in vary)), vary,
                        require=require, **TINY)


# ---------------------------------------------------------------------- specs and demands
def test_value_specs():
    p = sw.sweep_parameters("cmos")["exposure_s"]
    assert sw.parse_values("--vary", p, "1e-3, 2e-3,3e-3") == [1e-3, 2e-3, 3e-3]
    assert sw.parse_values("--vary", p, "0.001:0.004:0.001") == [0.001, 0.002, 0.003, 0.004]  # stop included
    log = sw.parse_values("--vary", p, "log:1e-5:1e-2:4")
    assert log == pytest.approx([1e-5, 1e-4, 1e-3, 1e-2])
    level = sw.sweep_parameters("spikeone")["threshold_level"]
    assert sw.parse_values("--vary", level, "all") == list(range(16))
    assert sw.parse_values("--vary", level, "0:15:5") == [0, 5, 10, 15]
    assert sw.parse_values("--vary", sw.sweep_parameters("spikeone")["photon_noise"], "true,false") == [True, False]


@pytest.mark.parametrize("spec, needle", [("5:1:1", "no points"), ("log:1e-3:1e-2:0", "no points"), ("", "no values"),
                                          ("1:2:0", "step"), ("log:0:1:3", "> 0"), ("abc", "not a number")])
def test_bad_value_specs(spec, needle):
    with pytest.raises(ViformError, match=needle) as err:
        sw.parse_values("vary_texts exposure_s=" + spec, sw.sweep_parameters("cmos")["exposure_s"], spec)
    assert str(err.value).startswith("vary_texts")


def test_require_parsing_and_checks():
    ds = sw.parse_require("dr_captured_db>=120, edge_width_px<=2")
    assert [d.text() for d in ds] == ["dr_captured_db>=120", "edge_width_px<=2"]
    assert ds[0].met(121.0) and not ds[0].met(119.0) and not ds[0].met(math.nan)
    assert ds[0].shortfall(110.0) == pytest.approx(10.0) and ds[1].shortfall(5.0) == pytest.approx(3.0)
    with pytest.raises(ViformError, match="'blur' is not a metric; allowed: psnr_log_db"):
        sw.parse_require("blur<=2")
    for bad in ("dr_captured_db>>3", "dr_captured_db>=abc", "dr_captured_db>=nan", "dr_captured_db"):
        with pytest.raises(ViformError, match="^require"):
            sw.parse_require(bad)


def test_unknown_parameter_names_the_allowed_ones():
    with pytest.raises(ViformError, match=r"'exposure' is not a parameter of cmos; allowed: .*exposure_s"):
        sw.parse_vary(["exposure=1e-3"], ["cmos"])
    # a setting the sensor refuses is refused before any work, naming the parameter and the value
    with pytest.raises(ViformError, match=r"^settings: sensor 'cmos' at exposure_s=0.05"):
        sw.make_point_sensor("cmos", {"exposure_s": 0.05})  # longer than the 30 fps frame period
    with pytest.raises(ViformError, match=r"^vary: sensor 'cmos' at exposure_s=0.05"):
        sw.make_plan("dilemma", ["cmos"], ["exposure_s=0.05"], **TINY)


def test_points_default_once_and_seeds_are_per_point():
    plan = tiny_plan(["spikeone:threshold_level=11,12,13"])
    assert len(plan.points) == 3  # level 12 is the preset's default: one point, not two
    assert sum(p.is_default for p in plan.points) == 1
    seeds = {p.point_id: sw.point_seed(3, p) for p in plan.points}
    assert len(set(seeds.values())) == 3
    again = tiny_plan(["spikeone:threshold_level=13,12"])  # other order, fewer points: same ids and seeds
    assert {p.point_id: sw.point_seed(3, p) for p in again.points}.items() <= seeds.items()


def test_answer_best_and_nearest_miss():
    recs = [{"point_id": str(i), "sensor": s, "settings": {"x": i}, "label": f"{s} {i}", "metrics": m}
            for i, (s, m) in enumerate([("a", {"dr_captured_db": 130.0, "edge_width_px": 1.0, "psnr_log_db": 20.0}),
                                        ("a", {"dr_captured_db": 125.0, "edge_width_px": 1.5, "psnr_log_db": 25.0}),
                                        ("b", {"dr_captured_db": 100.0, "edge_width_px": 1.0, "psnr_log_db": 30.0}),
                                        ("b", {"dr_captured_db": 119.0, "edge_width_px": 3.0, "psnr_log_db": 10.0}),
                                        ("b", {"dr_captured_db": 60.0, "edge_width_px": math.nan,
                                               "psnr_log_db": 40.0})])]
    ans = sw.answer(recs, sw.parse_require("dr_captured_db>=120,edge_width_px<=2"))
    assert ans["per_sensor"]["a"]["meets"] and ans["per_sensor"]["a"]["best"] == "1"  # higher PSNR of the two
    b = ans["per_sensor"]["b"]
    assert not b["meets"] and b["best"] == "2"  # one demand missed (by 20 dB) beats two missed
    assert [m["demand"] for m in b["misses"]] == ["dr_captured_db>=120"] and b["misses"][0]["shortfall"] == 20.0
    assert ans["meeting"] == ["0", "1"]
    assert "a meets" in ans["sentences"][0]


def test_no_demands_means_nothing_meets():
    """Without demands the answer names each sensor's best point by the objective and says nothing was
    demanded: no point "meets", and an objective a sensor does not define is said so (not "-inf")."""
    recs = [{"point_id": "1", "sensor": "cmos", "settings": {"exposure_s": 1e-3}, "label": "cmos 1",
             "metrics": {"psnr_log_db": 22.0}},
            {"point_id": "2", "sensor": "cmos", "settings": {}, "label": "cmos (default)",
             "metrics": {"psnr_log_db": 19.0}},
            {"point_id": "3", "sensor": "gated", "settings": {}, "label": "gated (default)",
             "metrics": {"psnr_log_db": math.nan}},
            {"point_id": "4", "sensor": "seed003-overflow", "settings": {}, "label": "overflow", "metrics": {},
             "skipped": "its frame is longer than the clip"}]
    ans = sw.answer(recs, [])
    assert ans["meeting"] == [] and all(v["meets"] is None for v in ans["per_sensor"].values())
    assert ans["per_sensor"]["cmos"]["best"] == "1" and math.isnan(ans["per_sensor"]["gated"]["objective"])
    text = " ".join(ans["sentences"])
    assert ans["sentences"][0].startswith("No demands were given") and " meets " not in text
    assert "psnr_log_db is not defined for it here" in text and "inf" not in text
    assert ans["not_scored"] == {"seed003-overflow": "its frame is longer than the clip"}
    assert "seed003-overflow: not scored on this scene" in text


def test_tracking_needs_objects_in_the_clip():
    """A scene whose object truth is empty over the clip (translating) is refused for tracking, naming the
    parameter; one with objects is planned."""
    with pytest.raises(ViformError, match=r"^tracking: scene 'translating' has no objects to track"):
        sw.make_plan("translating", ["cmos"], ["exposure_s=1e-3"], tracking=True, **TINY)
    sw.make_plan("multi-object", ["cmos"], ["exposure_s=1e-3"], tracking=True, **TINY)


def test_library_errors_name_the_parameter():
    """The library speaks its parameter names, never a command's flags."""
    cases = [(dict(duration_s=20.0), "duration_s = 20 s is not allowed"), (dict(height=8), "height = 8"),
             (dict(instants_s=[0.5]), "instants_s: instant 0.5"), (dict(spike_image="x"), "spike_image = 'x'"),
             (dict(objective="blur"), "objective: 'blur'"), (dict(require="blur<=2"), "require: 'blur'")]
    for kw, needle in cases:
        with pytest.raises(ViformError) as err:
            sw.make_plan("dilemma", ["cmos"], None, **{**TINY, **kw})
        assert str(err.value).startswith(needle) and "--" not in str(err.value), str(err.value)
    with pytest.raises(ViformError, match=r"^sensors: 'nosuch' is not a sensor a sweep can vary"):
        sw.make_plan("dilemma", ["nosuch"], None, **TINY)
    with pytest.raises(ViformError, match=r"^vary_texts exposure=1e-3: 'exposure' is not a parameter"):
        sw.make_plan("dilemma", ["cmos"], ["exposure=1e-3"], **TINY)
    plan = sw.make_plan("dilemma", ["cmos"], None, **TINY)
    with pytest.raises(ViformError, match=r"^workers = -1 is not allowed"):
        sw.sweep(plan, "/tmp/never-written", workers=-1, progress=False)
    with pytest.raises(ViformError, match=r"^memory_limit = 'lots' is not allowed"):
        sw.sweep(plan, "/tmp/never-written", workers=1, memory_limit="lots", progress=False)
    assert not Path("/tmp/never-written").exists()
    # no string in the package's source names a flag
    for path in Path(sw.__file__).parent.glob("*.py"):
        assert not re.search(r"[\"'](?:[^\"'\n]*\s)?--[a-z]", path.read_text()), path


def test_scene_parameters_are_varied_like_a_sensors():
    """scene:PARAM=SPEC multiplies every sensor's points by the scene's values; each point records its scene
    setting (label, seed, table column); a parameter the scene lacks, a value it refuses and one set twice
    are refused before any work."""
    space = sw.scene_parameters("dilemma")
    assert {"brightness", "speed", "lamp_lux"} <= set(space) and space["brightness"].default == 1.0
    assert sw.scene_parameters("not-a-scene.png") == {}
    plan = sw.make_plan("dilemma", ["cmos"], ["cmos:exposure_s=1e-4", "scene:brightness=0.1,10"], **TINY)
    assert plan.vary["scene"] == {"brightness": [0.1, 10.0]} and len(plan.points) == 4  # (1e-4, default) × 2
    assert len({p.point_id for p in plan.points}) == 4 and len({sw.point_seed(3, p) for p in plan.points}) == 4
    dim = [p for p in plan.points if dict(p.scene) == {"brightness": 0.1}]
    assert len(dim) == 2 and all(p.label().endswith("· scene brightness=0.1") for p in dim)
    assert all(dict(p.swept)["scene.brightness"] == 0.1 for p in dim)
    # without scene:…, points keep the ids (and seeds) they always had
    plain = sw.make_plan("dilemma", ["cmos"], ["cmos:exposure_s=1e-4"], **TINY)
    assert {p.point_id for p in plain.points} == {sw.Point(p.sensor, p.settings).point_id for p in plain.points}
    bad = [(["scene:nosuch=1"], {}, r"^vary_texts scene:nosuch=1: 'nosuch' is not a numeric parameter of the scene"),
           (["scene:brightness=-1"], {}, r"^vary: the scene at brightness=-1 cannot be made"),
           (["scene:brightness=1,2"], {"scene_options": {"brightness": 2.0}}, r"^vary: the scene's 'brightness' is"),
           (["nosuch:brightness=1"], {}, r"sensor 'nosuch' is not in this sweep")]
    for texts, kw, needle in bad:
        with pytest.raises(ViformError, match=needle):
            sw.make_plan("dilemma", ["cmos"], texts, **TINY, **kw)


def test_a_scene_sweep_answers_per_scene_setting(tmp_path):
    """Ten times more light leaves fewer pixels under the noise floor of the same camera; each scene setting
    gets its own answer, and the table has a column per varied scene parameter."""
    plan = sw.make_plan("dilemma", ["cmos"], ["scene:brightness=0.1,10"], require="underexposed_fraction<=0.1",
                        **TINY)
    doc = sw.sweep(plan, tmp_path, workers=0, progress=False)
    under = {r["scene"]["brightness"]: r["metrics"]["underexposed_fraction"] for r in doc["records"]}
    assert under[0.1] > under[10.0]
    per = doc["answer"]["per_sensor"]
    assert set(per) == {"cmos · scene brightness = 0.1", "cmos · scene brightness = 10"}
    assert per["cmos · scene brightness = 0.1"]["scene"] == {"brightness": 0.1}
    assert [s for s in doc["answer"]["sentences"] if s.startswith("At scene brightness = ")]
    table = sw.read_table(tmp_path / "sweep.zarr")
    assert sorted(table["parameter/scene.brightness"]) == [0.1, 10.0]


def test_device_is_checked_before_any_work(tmp_path):
    """device: cpu, cuda or auto, with every simulation's messages; cuda only for a sweep with a spike sensor,
    and only where a GPU is found; auto is the CPU where there is none, and for a sweep without a spike sensor."""
    with pytest.raises(ViformError, match=r"^device = 'gpu' is not allowed: use one of cpu, cuda, auto$"):
        sw.check_device("gpu", ["spikeone"])
    with pytest.raises(ViformError, match=r"^device = 'cuda' runs the spike camera's simulation on a GPU; this "
                                          r"sweep has no spike sensor"):
        sw.check_device("cuda", ["cmos"])
    assert sw.check_device("cpu", ["cmos"]) == "cpu"
    assert sw.check_device("auto", ["cmos"]) == "cpu"
    from viform.sensors.spike_cuda import cuda_available

    if not cuda_available():
        plan = sw.make_plan("dilemma", ["spikeone"], None, **TINY)
        assert sw.check_device("auto", ["spikeone"]) == "cpu"
        with pytest.raises(ViformError, match=r"^device = 'cuda': numba-cuda finds no CUDA GPU on this machine "
                                              r"\(use cpu or auto\)$|^device = 'cuda' needs numba-cuda"):
            sw.sweep(plan, tmp_path / "never", device="cuda", workers=0, progress=False)
        assert not (tmp_path / "never").exists()


CUDA_CHILD = """
import json, warnings
import numpy as np
warnings.simplefilter("ignore")  # uint64 hash arithmetic wraps in the simulator's NumPy scalars
from viform.measure import sweep as sw
context = sw.SweepContext("translating", 8, 12, 0.001, (0.0005,), 3, "interval")
point = sw.Point("spikeone", (("threshold_level", 0),))
gpu, cpu = (sw.run_point(context, point, device=d) for d in ("cuda", "cpu"))
print(json.dumps({"metrics": gpu["record"]["metrics"] == cpu["record"]["metrics"],
                  "images": bool(np.array_equal(gpu["images"], cpu["images"], equal_nan=True)),
                  "device": gpu["record"].get("device"), "cpu_device": cpu["record"].get("device", "cpu")}))
"""


def test_cuda_device_gives_the_cpu_points_in_the_simulator():
    """A point shot with device='cuda' (numba-cuda's simulator, no GPU needed) scores exactly as on the CPU
    and records its device."""
    pytest.importorskip("numba.cuda", reason="numba-cuda is not installed")
    env = {**__import__("os").environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": str(Path(sw.__file__).parents[3])}
    run = subprocess.run([sys.executable, "-c", CUDA_CHILD], env=env, capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert result == {"metrics": True, "images": True, "device": "cuda", "cpu_device": "cpu"}


# ---------------------------------------------------------------------- running
@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The reference: a spike + CMOS sweep run in this process, no dask."""
    plan = tiny_plan(["spikeone:threshold_level=0,15", "cmos:exposure_s=1e-4,1e-3"],
                     require="underexposed_fraction<=0.5")
    out = tmp_path_factory.mktemp("serial")
    return plan, out, sw.sweep(plan, out, workers=0, progress=False)


def _same(a, b):
    assert [r["point_id"] for r in a] == [r["point_id"] for r in b]
    for x, y in zip(a, b, strict=True):
        assert x["seed"] == y["seed"]
        for k, v in x["metrics"].items():
            w = y["metrics"][k]
            assert v == w or (isinstance(v, float) and math.isnan(v) and math.isnan(w)), (x["label"], k, v, w)


def test_identical_results_with_one_and_two_workers(serial, tmp_path):
    """The same points on a dask cluster of 1 and of 2 workers give the same metrics and images as in-process."""
    from distributed import Client, LocalCluster

    plan, out, ref = serial
    for n in (1, 2):
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
                Client(cluster) as client:
            doc = sw.sweep(plan, tmp_path / f"w{n}", client=client, progress=False)
        assert doc["computed"] == len(plan.points) and doc["workers"] == n
        _same(ref["records"], doc["records"])
        for r in ref["records"]:
            np.testing.assert_array_equal(sw.load_images(out, r["point_id"]),
                                          sw.load_images(tmp_path / f"w{n}", r["point_id"]))


def test_own_local_cluster_gives_the_same_points(serial, tmp_path):
    """workers=2 starts the sweep's own LocalCluster (its settings: no profiler, no work stealing), in
    guided batches of points; the points equal the in-process ones, and this process's dask settings
    are left as they were."""
    plan, out, ref = serial
    # a fresh process, where distributed is not imported yet (as on the command line)
    code = (f"import dask, json\nfrom viform.measure import sweep as sw\n"
            f"plan = sw.make_plan('dilemma', ['cmos'], ['cmos:exposure_s=1e-4,1e-3'], **{TINY!r})\n"
            f"doc = sw.sweep(plan, {str(tmp_path)!r}, workers=2, progress=False)\n"
            f"print(json.dumps([doc['workers'], doc['computed'], doc['computed_here'] >= 1, "
            f"dask.config.get('distributed.scheduler.work-stealing')]))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800,
                         env={**__import__("os").environ, "PYTHONPATH": str(Path(sw.__file__).parents[3])})
    assert run.returncode == 0, run.stderr[-3000:]
    assert json.loads(run.stdout.strip().splitlines()[-1]) == [2, 3, True, True]
    doc = json.loads((tmp_path / "sweep.json").read_text())
    _same([r for r in ref["records"] if r["sensor"] == "cmos"], [sw._restore(r) for r in doc["points"]])
    assert sw.batches(list(range(2)), 2) == [[0], [1]]


def test_own_local_cluster_asks_for_a_points_modules(monkeypatch):
    """The sweep's own LocalCluster is opened with a point's modules to preload in its fork server
    (``tests/test_parallel.py`` checks that a worker then finds them imported)."""
    from viform.measure.sweep import run

    asked = {}
    monkeypatch.setattr(run, "open_client", lambda *args, **kwargs: asked.update(kwargs))
    run._open(1, None, "auto")
    assert asked["preload"] == run.WORKER_MODULES == ("viform.measure.sweep.run",)


class _FakeCluster:
    closed = 0

    def close(self):
        _FakeCluster.closed += 1


def test_points_are_shot_here_while_the_cluster_starts():
    """While its own cluster starts, the sweep shoots one point of each sensor here (the kernels compiled once,
    before any worker needs them), then more until the cluster is up; the rest go to the workers."""
    import threading

    points = [sw.Point(s, (("x", i),)) for s in ("a", "b") for i in range(4)]  # a0..a3, b0..b3
    shot, up = [], threading.Event()

    def here(p):
        shot.append(p)
        if len(shot) == 3:  # the cluster comes up during the third point
            up.set()

    def start():
        up.wait(60)
        return "client", "cluster"

    client, cluster, left = sw.run._start_while_shooting(start, points, here, lambda: len(shot), "out")
    assert (client, cluster) == ("client", "cluster")
    assert shot[:2] == [points[0], points[4]]  # a0, b0: one of each sensor first
    assert len(shot) >= 3 and sorted(map(points.index, shot + left)) == list(range(8))
    assert not set(map(points.index, shot)) & set(map(points.index, left))

    def fail():
        raise ViformError("could not start 2 local dask worker process(es) (killed); nothing was written: "
                          "run the command again")

    shot.clear()
    with pytest.raises(ViformError, match=r"^could not start 2 local dask worker process\(es\) \(killed\); 2 points "
                                          r"are stored, each whole, in '.*points': run the same sweep again"):
        sw.run._start_while_shooting(fail, points, here, lambda: len(shot), "out")

    def boom(p):
        raise RuntimeError("a point failed")

    with pytest.raises(RuntimeError, match="a point failed"):  # the cluster that came up is closed
        sw.run._start_while_shooting(lambda: (_FakeCluster(), _FakeCluster()), points, boom, lambda: 0, "out")
    assert _FakeCluster.closed == 2


class _FakeClient(_FakeCluster):
    def scheduler_info(self):
        return {"workers": {}}


def test_own_cluster_is_closed_while_the_results_are_written(tmp_path, monkeypatch):
    """A finished sweep's own cluster is closed in a thread: the caller's ``close_later`` gets it to join after
    writing its results (sweep() joins it itself without one); after a failure it is closed before raising."""
    plan = tiny_plan(["cmos:exposure_s=1e-4,1e-3"])

    def start_here(start, todo, here, computed, out):  # the cluster "comes up" after every point is shot here
        for p in todo:
            here(p)
        return _FakeClient(), _FakeCluster(), []

    monkeypatch.setattr(sw.run, "_start_while_shooting", start_here)
    _FakeCluster.closed = 0
    closing = []
    doc = sw.sweep(plan, tmp_path / "a", workers=2, progress=False, close_later=closing)
    assert doc["computed_here"] == len(plan.points) and (tmp_path / "a" / "sweep.json").exists()
    assert len(closing) == 1 and closing[0].name == "viform-sweep-close"
    closing[0].join(60)
    assert _FakeCluster.closed == 2
    assert {"cluster_up_s", "points_s", "closed_s", "store_s"} <= set(doc["timings"])

    sw.sweep(plan, tmp_path / "b", workers=2, progress=False)  # no close_later: joined before returning
    assert _FakeCluster.closed == 4

    def start_fail(start, todo, here, computed, out):
        return _FakeClient(), _FakeCluster(), todo  # points left for workers that cannot take them

    monkeypatch.setattr(sw.run, "_start_while_shooting", start_fail)
    closing = []
    with pytest.raises(AttributeError):  # the fake client has no submit
        sw.sweep(plan, tmp_path / "c", workers=2, progress=False, close_later=closing)
    assert closing == [] and _FakeCluster.closed == 6

    class _BadCluster(_FakeCluster):
        def close(self):
            raise RuntimeError("could not close")

    monkeypatch.setattr(sw.run, "_start_while_shooting", lambda *a: (start_here(*a)[0], _BadCluster(), []))
    with pytest.raises(RuntimeError, match="could not close"):  # said by the join, in the caller's thread
        sw.sweep(plan, tmp_path / "d", workers=2, progress=False)


def test_tasks_shrink_toward_the_end():
    """Guided batches: each task takes half the points left per worker (strided through the plan), the last
    ones a point each; every point once."""
    tasks = sw.batches(list(range(32)), 2)
    assert [len(t) for t in tasks] == [8, 6, 5, 4, 3, 2, 1, 1, 1, 1]
    assert sorted(sum(tasks, [])) == list(range(32))
    assert tasks[0] == [0, 10, 20, 30, 1, 11, 21, 31]  # a mix of the plan's settings
    assert [len(t) for t in sw.batches(list(range(7)), 1)] == [4, 2, 1]
    assert sw.batches(list(range(5)), 2, share=0) == [[0], [1], [2], [3], [4]]


def test_table_and_physics(serial):
    """sweep.zarr holds one row per point; a lower threshold sees darker light in the same clip (fewer pixels
    under-exposed) and the spike camera's range in a clip stays within its 20·lg(clock · clip) bound."""
    plan, out, doc = serial
    table = sw.read_table(out / "sweep.zarr")
    assert list(table["point_id"]) == [p.point_id for p in plan.points]
    assert table["metric/psnr_log_db"].shape == (len(plan.points),)
    spike = {r["settings"].get("threshold_level", 12): r["metrics"] for r in doc["records"]
             if r["sensor"] == "spikeone"}
    under = [spike[level]["underexposed_fraction"] for level in (0, 12, 15)]
    assert under[0] < under[1] < under[2]
    # seed 000 §3.3: floor Q/(η·T) (one spike per clip), ceiling Q·f/η: DR ≤ 20·lg(f·T), ± a factor 2 at each
    # end for the "rendered within a factor of 2" rule of the metric
    bound = 20 * math.log10(40e3 * TINY["duration_s"]) + 20 * math.log10(4)
    assert all(m["dr_captured_db"] <= bound for m in spike.values())
    # the integration time is each pixel's interval (Q/(η·E), seed 000 §3.3) where the scene moves: it
    # grows with the threshold (Q = (level + 1)·1 250 e⁻), by about the ratio of Q (16 from level 0 to 15,
    # less where level 15's dim intervals are cut by the 12 ms clip), and the latency is one tick more
    res = [spike[level]["time_resolution_s"] for level in (0, 12, 15)]
    assert res[0] < res[1] < res[2] and res[2] / res[0] > 8
    assert all(spike[lv]["latency_s"] == pytest.approx(spike[lv]["time_resolution_s"] + 1 / 40e3)
               for lv in (0, 12, 15))
    assert doc["answer"]["per_sensor"]["spikeone"]["meets"]  # level 0 sees most of the scene
    assert doc["answer"]["per_sensor"]["spikeone"]["settings"] == {"threshold_level": 0}


def test_resume_after_kill_and_extend(serial, tmp_path):
    """A sweep killed after 2 points recomputes only the others; a longer sweep reuses every stored point."""
    plan, _, ref = serial
    vary = ["cmos:exposure_s=1e-4,1e-3"]
    code = (f"from viform.measure import sweep as sw\n"
            f"plan = sw.make_plan('dilemma', ['cmos'], {vary!r}, **{TINY!r})\n"
            f"sw.sweep(plan, {str(tmp_path)!r}, workers=0, progress=False, crash_after_points=2)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800,
                         env={**__import__("os").environ, "PYTHONPATH": str(Path(sw.__file__).parents[3])})
    assert run.returncode == 70, run.stderr[-2000:]
    assert len(list((tmp_path / "points").glob("*.json"))) == 2 and not (tmp_path / "sweep.json").exists()
    plan2 = sw.make_plan("dilemma", ["cmos"], vary, **TINY)
    doc = sw.sweep(plan2, tmp_path, workers=0, progress=False)
    assert (doc["computed"], doc["reused"]) == (1, 2)
    wanted = [r for r in ref["records"] if r["sensor"] == "cmos"]
    _same(wanted, doc["records"])
    more = sw.make_plan("dilemma", ["cmos"], ["cmos:exposure_s=1e-4,1e-3,3e-3"], **TINY)
    doc = sw.sweep(more, tmp_path, workers=0, progress=False)
    assert (doc["computed"], doc["reused"]) == (1, 3)
    assert json.loads((tmp_path / "sweep.json").read_text())["n_points"] == 4
    with pytest.raises(ViformError, match="other settings"):  # another clip length: not this sweep
        sw.sweep(sw.make_plan("dilemma", ["cmos"], vary, **{**TINY, "duration_s": 0.02}), tmp_path, workers=0,
                 progress=False)


def test_tracking_scores_join_the_table(tmp_path):
    """--tracking adds the comparison tracker's scores as columns; a 30 fps camera has one frame in a 40 ms
    clip: from one frame the back end finds at most the objects that stand out of their background, never
    all of them, so it misses objects and falls short of the demand."""
    plan = sw.make_plan("multi-object", ["cmos"], ["cmos:exposure_s=1e-3"], height=32, width=48, duration_s=0.04,
                        tracking=True, require="tracking_hota>=0.5")
    doc = sw.sweep(plan, tmp_path, workers=0, progress=False)
    table = sw.read_table(tmp_path / "sweep.zarr")
    assert {"metric/tracking_hota", "metric/tracking_objects_missed"} <= set(table)
    hota = np.asarray(table["metric/tracking_hota"], float)
    assert np.all((hota >= 0) & (hota < 0.5)), hota
    assert np.all(table["metric/tracking_objects_missed"] >= 1)
    assert not doc["answer"]["per_sensor"]["cmos"]["meets"]


def test_a_renamed_camera_keeps_its_points_noise():
    """compare/sweep's 'spike' became 'spikeone': its points are seeded under the old name, so a sweep
    gives the same bits (and scores) at the same settings and sweep seed as before the rename."""
    import hashlib

    point = sw.Point("spikeone", (("threshold_level", 3),))
    old_key = '["spike",[["threshold_level",3]]]'
    expected = int.from_bytes(hashlib.sha256(f"7/{old_key}".encode()).digest()[:8], "little") & ((1 << 63) - 1)
    assert sw.point_seed(7, point) == expected
    assert sw.point_seed(7, sw.Point("cmos", ())) != sw.point_seed(7, sw.Point("cmos-short", ()))


def test_a_failed_close_never_hides_the_callers_own_error():
    """The threads closing a sweep's cluster are all joined; what closing raised reaches the caller only
    when the caller itself did not fail (its own error, say a full disk while storing, is the one shown)."""
    from viform.measure.sweep import run

    class Part:
        def __init__(self, fails):
            self.fails, self.closed = fails, False

        def close(self):
            self.closed = True
            if self.fails:
                raise OSError("close failed")

    def closing(*fails):
        parts = [Part(f) for f in fails]
        threads = [run._Closing([p]) for p in parts]
        for t in threads:
            t.start()
        return threads, parts

    threads, parts = closing(True, False)
    run.join_closing(threads, failed=True)  # the caller's own error goes on; the close error is not raised
    assert all(p.closed for p in parts)
    threads, parts = closing(False, True)
    with pytest.raises(OSError, match="close failed"):
        run.join_closing(threads, failed=False)
    assert all(p.closed for p in parts) and not any(t.is_alive() for t in threads)
    run.join_closing(closing(False, False)[0], failed=False)
