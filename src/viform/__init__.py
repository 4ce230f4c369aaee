"""viform: simulation and processing of next-generation image sensors.

Data flows one way: scene (``viform.light``) → sensor (``viform.sensors``) → output
(``viform.stream`` spike streams, frames) → processing (``viform.imaging``,
``viform.coding``, ``viform.isp``) → measurement and report (``viform.measure``,
``viform.report``).
"""

__version__ = "0.1.0"
