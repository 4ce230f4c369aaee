"""viform: simulation and processing of next-generation image sensors.

Data flows one way: scene (``viform.light``) → sensor (``viform.sensors``) → output
(``viform.stream`` spike streams, frames) → processing (``viform.imaging``,
``viform.coding``, ``viform.isp``) → measurement and report (``viform.measure``,
``viform.report``).
"""

import os as _os

__version__ = "0.1.0"

if _os.environ.get("VIFORM_SHARE_COMPILES") == "1":
    # processes started together (a test run's workers and the commands they start, parallel jobs)
    # compile each kernel once between them: viform._numba_cache
    from viform._numba_cache import share_compiles as _share_compiles

    _share_compiles()
