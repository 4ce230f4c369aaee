"""Distributed runs under faults (issue 39.7): ``dataset`` and ``sweep`` on dask, with a worker
process or the scheduler killed (SIGKILL) while they run.

A trial runs the command in its own process, kills one process of its cluster at a moment
(the first worker up, the first temporary file of a clip, the first finished clip or point, or,
in long runs, a random delay), and waits for the command without a deadline of its own (a hang is
past :data:`HANG_S`, minutes where a run takes seconds). Allowed outcomes:

``whole``
    exit 0, and every output identical to an undisturbed run's (dask ran the lost task again);
``stopped``
    exit 2 with one line that says what is done and that running the command again resumes;
    a second run (with a live cluster) then ends ``whole``.

Failures: ``wrong`` (exit 0, or the resumed run, with an output that differs or a clip that does
not verify), ``unclear`` (stopped without one such line), ``internal`` (another exit status),
``hang``, ``leftovers`` (temporary files left once the runs are over).

Run a bigger campaign (outside the suite) with::

    python tests/cli/test_fuzz_workers.py --cases 24 --seed 1
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

psutil = pytest.importorskip("psutil")
pytest.importorskip("distributed")

#: A command still running after this long is a hang (an undisturbed run takes seconds).
HANG_S = 1800.0


def _spike_sensor() -> str:
    from viform.measure.sweep import SWEEP_SENSORS

    return "spikeone" if "spikeone" in SWEEP_SENSORS else "spike"  # (an older viform: "spike")


COMMANDS = {
    "dataset": ["dataset", "--scenes", "translating", "--clips", "4", "--duration", "0.005", "--height", "32",
                "--width", "48", "--no-progress"],
    "sweep": ["sweep", "translating", "--sensor", _spike_sensor(), "--vary", "threshold_level=1,2,3", "--duration",
              "0.005", "--height", "32", "--width", "48", "--no-progress"],
}
TARGETS = ("worker", "scheduler")
#: Moments of the kill, by event (``delay``: a random fraction of an undisturbed run, long runs only).
MOMENTS = ("workers-up", "first-output", "delay")


# ---------------------------------------------------------------- clusters and runs
class Cluster:
    """A dask scheduler and ``n`` single-thread workers (each under a nanny that restarts it), as
    separate processes, for ``--scheduler``."""

    def __init__(self, folder: Path, n: int = 2):
        file = folder / f"scheduler-{time.monotonic_ns()}.json"
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        self.scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                                           "127.0.0.1", "--port", "0", "--dashboard-address", ":0",
                                           "--scheduler-file", str(file)], **quiet)
        while not (file.exists() and file.read_text().strip()):
            if self.scheduler.poll() is not None:
                raise RuntimeError("the dask scheduler did not start")
            time.sleep(0.05)
        self.address = json.loads(file.read_text())["address"]
        self.workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file",
                                         str(file), "--nthreads", "1", "--nworkers", str(n), "--no-dashboard"],
                                        **quiet)
        from distributed import Client

        with Client(self.address, timeout=HANG_S) as client:
            client.wait_for_workers(n, timeout=HANG_S)

    def close(self) -> None:
        for proc in (self.workers, self.scheduler):
            if proc.poll() is None:
                proc.terminate()
        for proc in (self.workers, self.scheduler):
            try:
                proc.wait(HANG_S)
            except subprocess.TimeoutExpired:
                proc.kill()


def worker_processes(pid: int) -> list:
    """The dask worker processes below ``pid`` (spawned by their nannies, or forked by multiprocessing's fork
    server: viform's own local clusters, :data:`viform._parallel.WORKER_START`)."""
    try:
        kids = psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []
    found = []
    for kid in kids:
        try:
            line = " ".join(kid.cmdline())
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        try:
            forked = "multiprocessing.forkserver" in " ".join(kid.parent().cmdline())
        except (psutil.NoSuchProcess, psutil.AccessDenied, AttributeError):
            forked = False
        if "spawn_main" in line or forked:
            found.append(kid)
    return found


def outputs_exist(kind: str, out: Path, what: str) -> bool:
    if kind == "dataset":
        folder = out / "spike"
        if not folder.is_dir():
            return False
        pattern = ".*.viform-tmp-*" if what == "temporary" else "*.dat.json"
        return any(folder.glob(pattern))
    return any((out / "points").glob("*.json")) if (out / "points").is_dir() else False


def _has_connect_timeout() -> bool:
    import viform.cli.dataset as dataset_cli

    return "connect_timeout_s" in {p.name for p in dataset_cli.dataset.params}


def run_trial(kind: str, target: str, moment: str, work: Path, rng, typical_s: float) -> dict:
    """One run of ``kind`` with one kill; returns what happened (before any rerun)."""
    out = work / "out"
    cluster = Cluster(work) if target == "scheduler" else None
    timeout = ["--connect-timeout", "10"] if _has_connect_timeout() else []  # (older viform: dask's 20 s)
    args = COMMANDS[kind] + ["--out", str(out)] + (["--scheduler", cluster.address, *timeout]
                                                     if cluster is not None else ["--workers", "2"])
    delay = rng.uniform(0.0, typical_s) if moment == "delay" else None
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "viform.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "VIFORM_DEBUG": ""})
    killed = None
    try:
        while proc.poll() is None and killed is None:
            if time.monotonic() - started > HANG_S:
                break
            if target == "scheduler":
                victims = [psutil.Process(cluster.scheduler.pid)]
            else:
                victims = worker_processes(proc.pid)
            ready = len(victims) >= (1 if target == "scheduler" else 2)
            due = {"workers-up": ready,
                   "first-output": ready and outputs_exist(kind, out, "temporary" if kind == "dataset" else "point"),
                   "delay": ready and delay is not None and time.monotonic() - started >= delay}[moment]
            if due:
                victim = victims[int(rng.integers(len(victims)))]
                try:
                    victim.kill()
                    killed = round(time.monotonic() - started, 2)
                except psutil.NoSuchProcess:
                    pass
            time.sleep(0.01)
        try:
            stdout, stderr = proc.communicate(timeout=max(1.0, HANG_S - (time.monotonic() - started)))
            rc = proc.returncode
        except subprocess.TimeoutExpired:
            proc.kill()
            stdout, stderr = proc.communicate()
            rc = "hang"
    finally:
        if cluster is not None:
            cluster.close()
    return {"rc": rc, "stderr": stderr, "stdout": stdout[-2000:], "killed_at_s": killed,
            "seconds": round(time.monotonic() - started, 1)}


def rerun(kind: str, work: Path) -> dict:
    """The same command again, undisturbed (on a fresh local cluster)."""
    out = work / "out"
    proc = subprocess.run([sys.executable, "-m", "viform.cli", *COMMANDS[kind], "--out", str(out),
                           "--workers", "2"], capture_output=True, text=True, timeout=HANG_S,
                          env={**os.environ, "VIFORM_DEBUG": ""})
    return {"rc": proc.returncode, "stderr": proc.stderr}


# ---------------------------------------------------------------- what a run leaves
def digest(kind: str, out: Path) -> str:
    """Every output that must not depend on faults (sidecars and records hold dates and timings)."""
    import warnings

    from viform.stream.io import open_spikes

    h = hashlib.blake2b(digest_size=16)
    if kind == "dataset":
        for path in sorted(p for p in out.rglob("*") if p.is_file()):
            rel = str(path.relative_to(out))
            if path.name.endswith(".json") and path.name != "manifest.json" or ".viform-" in path.name:
                continue
            h.update(rel.encode() + path.read_bytes())
        for dat in sorted((out / "spike").glob("*.dat")):  # every clip whole: data and sidecar agree
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                if not open_spikes(dat).verify()["verified"]:
                    return "a clip does not verify"
        return h.hexdigest()
    doc = json.loads((out / "sweep.json").read_text())
    for point in sorted(doc["points"], key=lambda p: p["point_id"]):
        h.update(json.dumps([point["point_id"], point["metrics"]], sort_keys=True).encode())
        images = out / "points" / f"{point['point_id']}.npz"
        if images.is_file():
            with np.load(images) as f:
                h.update(np.ascontiguousarray(f["lux"]).tobytes())
    return h.hexdigest()


def leftovers(out: Path) -> list[str]:
    return [str(p) for p in out.rglob("*") if ".viform-tmp" in p.name or ".viform-old" in p.name
            or "viform-pending" in p.name]


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.strip() and "%|" not in line
            and not line.startswith(("compiling ", "connecting to ", "viform: warning:"))]


def outcome(kind: str, trial: dict, work: Path, reference: str) -> tuple[str, dict]:
    out = work / "out"
    rc = trial["rc"]
    if rc == "hang":
        return "hang", trial
    lines = error_lines(trial["stderr"])
    if rc == 0:
        return ("whole" if digest(kind, out) == reference else "wrong"), trial
    if rc == 2:
        said = ("again" in lines[0] and ("done" in lines[0] or "stored" in lines[0])) or \
            "nothing was written" in lines[0] if len(lines) == 1 else False
        if not said:
            return "unclear", trial
        again = rerun(kind, work)
        trial["rerun"] = again
        if again["rc"] != 0:
            return "unclear", trial
        return ("stopped" if digest(kind, out) == reference else "wrong"), trial
    return "internal", trial


def reference_run(kind: str, work: Path) -> tuple[str, float]:
    """An undisturbed run in this process (sweep: ``--workers 0``; dataset: one worker thread, no
    processes): its output digest and its length, s."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from viform.cli import main

    started = time.monotonic()
    args = [*COMMANDS[kind], "--out", str(work / "out"), "--workers", "0" if kind == "sweep" else "1"]
    real = None
    import viform.datasets.build as build

    if kind == "dataset" and hasattr(build, "open_client"):  # (an older viform: a local cluster of one process)
        real = build.open_client

        def in_process(workers, scheduler, memory_limit, connect_timeout_s=20.0, preload=()):
            import logging

            from distributed import Client, LocalCluster

            cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0",
                                   silence_logs=logging.ERROR)
            return Client(cluster), cluster

        build.open_client = in_process
    err = io.StringIO()
    try:
        with redirect_stdout(io.StringIO()), redirect_stderr(err):
            rc = main(args)
    finally:
        if real is not None:
            build.open_client = real
    assert rc == 0, err.getvalue()[-2000:]
    return digest(kind, work / "out"), time.monotonic() - started


def campaign(cases: int, seed: int, kinds=tuple(COMMANDS), moments=MOMENTS, plan=None) -> dict:
    """``cases`` trials: every command × target × moment in turn (or the (command, target) pairs of ``plan``)."""
    rng = np.random.default_rng(seed)
    counts: dict[str, dict] = {}
    examples: list = []
    with tempfile.TemporaryDirectory(prefix="viform-workerfuzz-") as folder:
        folder = Path(folder)
        used = {k for k, _ in plan} if plan is not None else set(kinds)
        references = {kind: reference_run(kind, folder / f"reference-{kind}") for kind in kinds if kind in used}
        for case in range(cases):
            kind = kinds[case % len(kinds)]
            target = TARGETS[(case // len(kinds)) % len(TARGETS)]
            if plan is not None:
                kind, target = plan[case % len(plan)]
            moment = moments[(case // (len(kinds) * len(TARGETS))) % len(moments)]
            work = folder / f"case{case}"
            work.mkdir()
            trial = run_trial(kind, target, moment, work, rng, references[kind][1])
            result, trial = outcome(kind, trial, work, references[kind][0])
            tally = counts.setdefault(f"{kind}/{target}", {})
            tally["runs"] = tally.get("runs", 0) + 1
            tally[result] = tally.get(result, 0) + 1
            left = leftovers(work / "out")
            if left:
                tally["leftovers"] = tally.get("leftovers", 0) + 1
            if result not in ("whole", "stopped") or left or len(examples) < 6:
                examples.append({"case": case, "kind": kind, "target": target, "moment": moment, "outcome": result,
                                 "rc": trial["rc"], "killed_at_s": trial["killed_at_s"], "s": trial["seconds"],
                                 "errors": error_lines(trial["stderr"])[-3:], "leftovers": left[:3]})
            shutil.rmtree(work, ignore_errors=True)
    return {"cases": cases, "counts": counts, "examples": examples,
            "reference_s": {k: round(v[1], 1) for k, v in references.items()}}


# ---------------------------------------------------------------- the suite
def test_a_killed_worker_or_scheduler_never_leaves_a_half_written_run(tmp_path):
    """Two trials: a worker killed as the first clip is being written (dataset), the scheduler
    killed as the first point is stored (sweep). Each run ends whole, or stops in one line and
    resumes to the same outputs (the long campaign kills at other moments too)."""
    result = campaign(2, seed=3, moments=("first-output",), plan=[("dataset", "worker"), ("sweep", "scheduler")])
    bad = {k: {o: n for o, n in v.items() if o not in ("runs", "whole", "stopped")}
           for k, v in result["counts"].items()}
    assert all(not v for v in bad.values()), json.dumps(result, indent=1)[:6000]
    assert all(e["killed_at_s"] is not None for e in result["examples"]), result["examples"]  # the kills happened


def test_an_unreachable_scheduler_says_it_is_connecting_and_gives_up_in_time(tmp_path):
    """``--scheduler tcp://127.0.0.1:1``: a note first, then one line naming the timeout; nothing written."""
    for kind in COMMANDS:
        out = tmp_path / kind
        proc = subprocess.run([sys.executable, "-m", "viform.cli", *COMMANDS[kind], "--out", str(out), "--scheduler",
                               "tcp://127.0.0.1:1", "--connect-timeout", "0.5"], capture_output=True, text=True,
                              timeout=HANG_S)
        lines = [line for line in proc.stderr.splitlines() if line.strip() and not line.startswith("compiling ")]
        assert proc.returncode == 2 and len(lines) == 2, proc.stderr
        assert lines[0].startswith("connecting to the dask scheduler at tcp://127.0.0.1:1 (trying for up to 0.5 s")
        assert "could not connect within --connect-timeout = 0.5 s" in lines[1]
        assert not (out / "spike").exists() and not (out / "points").exists()


def main_cli() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=24)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", help="also write the whole result to this file")
    args = parser.parse_args()
    started = time.perf_counter()
    result = campaign(args.cases, args.seed)
    result["elapsed_s"] = round(time.perf_counter() - started, 1)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1, default=str))
    print(json.dumps(result, indent=1, default=str)[:20000])


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)
    main_cli()
