"""viform: simulation and processing of next-generation image sensors.

Data flows one way: scene (``viform.light``) → sensor (``viform.sensors``) → output
(``viform.stream`` spike streams, frames) → processing (``viform.imaging``,
``viform.coding``, ``viform.isp``) → measurement and report (``viform.measure``,
``viform.report``).
"""

import os as _os

__version__ = "0.1.0"

# numba runs its parallel kernels on an OpenMP team (its "omp" threading layer, the default on Linux),
# whose threads by default spin after each parallel region before they sleep (300,000 polls in GNU
# libgomp): CPU taken, on a machine with few cores, from the threads that work meanwhile (the tracker's
# reader and association threads, a test run's other worker). They wait passively unless the user chose
# otherwise; read when the OpenMP runtime loads, that is at the first parallel kernel (a runtime loaded
# earlier by another library keeps its own setting). Measured on 2 cores, each alternately: the test
# suite 7–11 % less wall time and CPU; `viform track` 10 % less CPU; the simulator's own kernels unchanged.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

if _os.environ.get("VIFORM_SHARE_COMPILES") == "1":
    # processes started together (a test run's workers and the commands they start, parallel jobs)
    # compile each kernel once between them: viform._numba_cache
    from viform._numba_cache import share_compiles as _share_compiles

    _share_compiles()
