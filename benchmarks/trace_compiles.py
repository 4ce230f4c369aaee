"""Which numba kernels a command compiles, under which signatures, and what each compile costs.

Runs a command (a pytest run, a CLI, a benchmark) with a numba compile listener installed in every
Python process it starts (the pytest-xdist workers and the subprocesses of tests too: a
``sitecustomize`` put first on ``PYTHONPATH`` registers the listener when numba is imported), then
prints, per dispatcher, every signature compiled, in how many processes, and the CPU-seconds of each
compile, most costly first, with the totals. Only real compiles count: numba's ``numba:compile``
event fires on a cache miss, never on a load from the on-disk cache.

A kernel listed with several signatures was specialised more than once (an argument passed once as
int64 and once as a literal or an omitted default, a read-only and a writable array, C and A layouts,
float32 and float64 scalars): each extra signature is a full compile that one consistent call form
would save. A signature compiled in more processes than one was compiled again by a process that
could have loaded it from the cache (see ``viform._numba_cache.share_compiles``).

CPU time is the compiling thread's (``time.thread_time``); a compile that triggers another (a kernel
calling a kernel not yet compiled) is split: "self" excludes the nested compiles, so the self times
add up to the total without counting anything twice.

Run::

    python benchmarks/trace_compiles.py --cold -- pytest -q -p no:cacheprovider tests/coding
    python benchmarks/trace_compiles.py --cold --json compiles.json -- pytest -q -p no:cacheprovider

``--cold`` gives the command an empty numba cache (``NUMBA_CACHE_DIR``) and an empty viform cache
(``VIFORM_CACHE_DIR``) in a temporary folder, removed afterwards; without it the command uses the
caches as they are (and then lists only what was missing). The command's total CPU (user + sys of
every process it started and waited for), the CPU of each Python process that exited normally (the
subprocesses of tests: start-up and cache loads), and the load average before and after are printed too.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

#: The ``sitecustomize`` module written for the traced processes. It imports nothing heavy: the
#: listener is registered by an import hook once ``numba.core.event`` is loaded by the process itself.
_SITE = r'''
import os, sys, threading, time, json, importlib.abc, importlib.util

_OUT = os.environ.get("TRACE_COMPILES_OUT")
_local = threading.local()
_write_lock = threading.Lock()


def _name(dispatcher):
    f = getattr(dispatcher, "py_func", None)
    return f"{getattr(f, '__module__', '?')}.{getattr(f, '__qualname__', repr(dispatcher))}"


def _install(event):
    class Listener(event.Listener):
        def on_start(self, ev):
            stack = getattr(_local, "stack", None)
            if stack is None:
                stack = _local.stack = []
            stack.append([time.thread_time(), time.perf_counter(), 0.0])

        def on_end(self, ev):
            stack = getattr(_local, "stack", None)
            if not stack:
                return
            t0, w0, nested = stack.pop()
            inclusive = time.thread_time() - t0
            if stack:
                stack[-1][2] += inclusive
            data = ev.data or {}
            rec = {"kind": "compile", "pid": os.getpid(), "name": _name(data.get("dispatcher")),
                   "sig": "(" + ", ".join(str(a) for a in data.get("args", ())) + ")",
                   "cpu_s": inclusive, "self_cpu_s": inclusive - nested,
                   "wall_s": time.perf_counter() - w0, "depth": len(stack)}
            with _write_lock:
                with open(_OUT, "a") as fh:
                    fh.write(json.dumps(rec) + "\n")

    event.register("numba:compile", Listener())


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path, target=None):
        if fullname != "numba.core.event":
            return None
        sys.meta_path.remove(self)
        try:
            spec = importlib.util.find_spec(fullname)
        finally:
            sys.meta_path.insert(0, self)
        if spec is None or spec.loader is None:
            return None
        exec_module = spec.loader.exec_module

        def run(module):
            exec_module(module)
            try:
                sys.meta_path.remove(self)
            except ValueError:
                pass
            _install(module)

        spec.loader.exec_module = run
        return spec


def _at_exit():
    import resource
    ru = resource.getrusage(resource.RUSAGE_SELF)
    rec = {"kind": "process", "pid": os.getpid(), "argv": sys.argv[:6], "cpu_s": ru.ru_utime + ru.ru_stime}
    with _write_lock:
        with open(_OUT, "a") as fh:
            fh.write(json.dumps(rec) + "\n")


if _OUT:
    sys.meta_path.insert(0, _Finder())
    import atexit
    atexit.register(_at_exit)
'''


def _load():
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def summarise(records: list[dict]) -> dict:
    """Per-dispatcher totals, the duplicated signatures, and the grand totals of ``records``."""
    by_name: dict[str, dict] = {}
    for r in records:
        d = by_name.setdefault(r["name"], {"self_cpu_s": 0.0, "sigs": {}})
        d["self_cpu_s"] += r["self_cpu_s"]
        s = d["sigs"].setdefault(r["sig"], {"self_cpu_s": 0.0, "compiles": 0, "pids": set()})
        s["self_cpu_s"] += r["self_cpu_s"]
        s["compiles"] += 1
        s["pids"].add(r["pid"])
    total = sum(r["self_cpu_s"] for r in records)
    # cost a consistent call form would save: every signature of a kernel but its costliest one
    extra_sig = 0.0
    # cost of compiling again what another process compiled (same kernel, same signature)
    repeated = 0.0
    for d in by_name.values():
        sigs = sorted(d["sigs"].values(), key=lambda s: -s["self_cpu_s"] / s["compiles"])
        extra_sig += sum(s["self_cpu_s"] / s["compiles"] for s in sigs[1:])
        repeated += sum(s["self_cpu_s"] * (s["compiles"] - 1) / s["compiles"] for s in sigs)
    return {
        "total_self_cpu_s": total,
        "compiles": len(records),
        "dispatchers": len(by_name),
        "signatures": sum(len(d["sigs"]) for d in by_name.values()),
        "extra_signature_cpu_s": extra_sig,
        "repeated_compile_cpu_s": repeated,
        "processes": len({r["pid"] for r in records}),
        "by_name": by_name,
    }


def report(summary: dict, top: int = 40, out=sys.stdout) -> None:
    by_name = summary["by_name"]
    order = sorted(by_name, key=lambda n: -by_name[n]["self_cpu_s"])
    print(f"\n{summary['compiles']} compiles of {summary['signatures']} signatures of "
          f"{summary['dispatchers']} dispatchers in {summary['processes']} processes: "
          f"{summary['total_self_cpu_s']:.1f} CPU-s", file=out)
    print(f"  of which extra signatures (a kernel's second, third… specialisation): "
          f"{summary['extra_signature_cpu_s']:.1f} CPU-s", file=out)
    print(f"  of which the same signature compiled again in another process: "
          f"{summary['repeated_compile_cpu_s']:.1f} CPU-s", file=out)
    print(f"\nCostliest {min(top, len(order))} dispatchers (self CPU-s, signatures):", file=out)
    for n in order[:top]:
        d = by_name[n]
        print(f"  {d['self_cpu_s']:7.2f}  {len(d['sigs']):2d}  {n}", file=out)
    multi = [n for n in order if len(by_name[n]["sigs"]) > 1]
    print(f"\nDispatchers compiled under more than one signature ({len(multi)}):", file=out)
    for n in multi:
        d = by_name[n]
        print(f"  {n}  ({d['self_cpu_s']:.2f} CPU-s)", file=out)
        for sig, s in sorted(d["sigs"].items(), key=lambda kv: -kv[1]["self_cpu_s"]):
            print(f"      {s['self_cpu_s']:7.2f} s  x{s['compiles']} in {len(s['pids'])} proc  {sig}", file=out)
    again = [(n, sig, s) for n in order for sig, s in by_name[n]["sigs"].items() if s["compiles"] > 1]
    if again:
        print(f"\nSame signature compiled more than once ({len(again)}):", file=out)
        for n, sig, s in sorted(again, key=lambda t: -t[2]["self_cpu_s"])[:top]:
            print(f"  {s['self_cpu_s']:7.2f} s  x{s['compiles']} in {len(s['pids'])} proc  {n}{sig}", file=out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     usage="%(prog)s [--cold] [--json FILE] [--top N] -- COMMAND ...")
    parser.add_argument("--cold", action="store_true", help="empty numba and viform caches for the command")
    parser.add_argument("--json", help="write the summary and every compile record here")
    parser.add_argument("--top", type=int, default=40, help="dispatchers to list (default 40)")
    parser.add_argument("command", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("no command given (put it after --)")

    work = tempfile.mkdtemp(prefix="trace-compiles-")
    try:
        site = os.path.join(work, "site")
        os.makedirs(site)
        with open(os.path.join(site, "sitecustomize.py"), "w") as fh:
            fh.write(_SITE)
        out = os.path.join(work, "compiles.jsonl")
        env = dict(os.environ, TRACE_COMPILES_OUT=out,
                   PYTHONPATH=os.pathsep.join(p for p in (site, os.environ.get("PYTHONPATH")) if p))
        if args.cold:
            env["NUMBA_CACHE_DIR"] = os.path.join(work, "numba-cache")
            env["VIFORM_CACHE_DIR"] = os.path.join(work, "viform-cache")
        print(f"load before: {_load()}  command: {' '.join(command)}", flush=True)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        wall0 = time.perf_counter()
        rc = subprocess.call(command, env=env)
        wall = time.perf_counter() - wall0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        user = after.ru_utime - before.ru_utime
        sys_ = after.ru_stime - before.ru_stime
        records = []
        if os.path.exists(out):
            with open(out) as fh:
                records = [json.loads(line) for line in fh if line.strip()]
        procs = [r for r in records if r.get("kind") == "process"]
        records = [r for r in records if r.get("kind", "compile") == "compile"]
        summary = summarise(records)
        report(summary, args.top)
        if procs:
            print(f"\nPython processes that exited normally: {len(procs)}, "
                  f"{sum(p['cpu_s'] for p in procs):.1f} CPU-s; costliest:")
            for p in sorted(procs, key=lambda p: -p["cpu_s"])[:10]:
                print(f"  {p['cpu_s']:7.2f}  {' '.join(p['argv'])[:100]}")
        print(f"\ncommand: exit {rc}, {wall:.1f} s wall, CPU user {user:.1f} s + sys {sys_:.1f} s = "
              f"{(user + sys_) / 60:.2f} CPU-min; load after: {_load()}")
        if args.json:
            by_name = {n: {"self_cpu_s": d["self_cpu_s"],
                           "sigs": {s: {"self_cpu_s": v["self_cpu_s"], "compiles": v["compiles"],
                                        "processes": len(v["pids"])} for s, v in d["sigs"].items()}}
                       for n, d in summary["by_name"].items()}
            with open(args.json, "w") as fh:
                json.dump({**summary, "by_name": by_name, "records": records, "processes_exited": procs,
                           "command": command,
                           "exit": rc, "wall_s": wall, "cpu_user_s": user, "cpu_sys_s": sys_}, fh, indent=1)
        return rc
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
