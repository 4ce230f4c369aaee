"""CLI start-up: CPU seconds of ``viform --help`` and of a 4-tick ``viform simulate``, beside the floors.

Each command runs ``--repeats`` times in a fresh process after one warm-up run (numba's caches and
the Gamma tables on disk, bytecode written); the figure is the least CPU time (user + system of
the child) over the runs, which is the least sensitive to the other work on a shared machine.
The floors, measured the same way in the same run: the interpreter alone, ``import numpy``, and
"numba ready" — ``import numba`` plus the first call of one cached viform kernel, which loads
numba's compiler target (every numba program pays it once). A 4-tick simulation costs its
start-up: what it costs above the floor is viform's own start-up.

It also lists the heavy optional libraries each command imports (``-X importtime``): none of
dask, zarr, matplotlib, OpenCV, TrackEval or scipy.special should load before the first tick,
and help and the catalogues should not load numba either.

Bytecode: with ``PYTHONDONTWRITEBYTECODE`` set (as on some shared machines), no ``.pyc`` is written for an
editable install's sources, so a start compiles every viform module that has none from source (≈ 0.13 CPU-s
for ``simulate``, counted as viform's own start-up; an installed wheel ships its ``.pyc``, and a ``.pyc``
already there is read either way). The header says whether it is set; ``--write-bytecode`` runs the commands
without it (the warm-up run writes the ``.pyc``).
Run: ``python benchmarks/bench_startup.py [--repeats 5] [--write-bytecode]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

HEAVY = ("dask", "distributed", "zarr", "matplotlib", "cv2", "trackeval", "scipy.special", "torch", "numba.cuda")


def cpu_seconds(command: list[str], repeats: int, env: dict | None = None) -> tuple[float, float]:
    """(least, median) CPU seconds of ``command`` over ``repeats`` runs after one warm-up run."""
    subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, env=env)
    times = []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, env=env)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    times.sort()
    return times[0], times[len(times) // 2]


def heavy_imports(command: list[str], env: dict | None = None, heavy=HEAVY) -> list[str]:
    """The modules of ``heavy`` (:data:`HEAVY`) that ``command`` (a ``python -m ...`` command) imports."""
    result = subprocess.run([command[0], "-X", "importtime", *command[1:]], capture_output=True, text=True, env=env)
    names = {line.rsplit("|", 1)[-1].strip() for line in result.stderr.splitlines() if line.startswith("import time:")}
    return [h for h in heavy if h in names]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--write-bytecode", action="store_true",
                        help="run the commands without PYTHONDONTWRITEBYTECODE (modules load from .pyc)")
    args = parser.parse_args(argv)
    env = None
    if args.write_bytecode:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    no_bytecode = bool((env if env is not None else os.environ).get("PYTHONDONTWRITEBYTECODE"))
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="viform-startup-") as tmp:
        out = str(Path(tmp) / "s.dat")
        simulate = [py, "-m", "viform", "simulate", "translating", "--duration", "0.0001", "--out", out]
        rows = [
            ("python (interpreter, site)", [py, "-c", "pass"]),
            ("import numpy", [py, "-c", "import numpy"]),
            ("numba ready (import, first cached kernel)",
             [py, "-c", "from viform.sensors._gamma import stream_keys; stream_keys(1, 1)"]),
            ("viform --help", [py, "-m", "viform", "--help"]),
            ("viform simulate --help", [py, "-m", "viform", "simulate", "--help"]),
            ("viform sensors (the catalogue)", [py, "-m", "viform", "sensors"]),
            ("viform simulate, 4 ticks, exact", simulate),
            ("viform simulate, 4 ticks, noise-free", [*simulate, "--no-noise"]),
        ]
        print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; least (median) CPU-s of "
              f"{args.repeats} runs; PYTHONDONTWRITEBYTECODE "
              + ("set: modules without a .pyc compile from source at every start (see --write-bytecode)" if no_bytecode
                 else "not set: modules load from .pyc"))
        floors = {}
        for name, command in rows:
            least, median = cpu_seconds(command, args.repeats, env)
            floors[name] = least
            extra = ""
            if command[1:3] == ["-m", "viform"]:
                # help and listings need no kernel (nor numba): their floor is NumPy; a simulation's is numba ready
                no_kernel = "--help" in command or "sensors" in command
                floor = "import numpy" if no_kernel else "numba ready (import, first cached kernel)"
                heavy = heavy_imports(command, env, HEAVY + ("numba",) if no_kernel else HEAVY)
                extra = (f"  above {floor.split(' (')[0]} {least - floors[floor]:+.3f}; "
                         f"heavy imports: {', '.join(heavy) or 'none'}")
            print(f"  {name:44s} {least:6.3f} ({median:.3f}){extra}", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
