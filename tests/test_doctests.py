"""The examples of a chosen list of modules run as doctests: what a docstring shows is what the code gives.

A module joins the list when its examples are small, fast and deterministic (a fixed seed, no files).
``viform.sensors.spike`` has an example too but is left out: running it took 67 s here (the
simulation's kernels), and the sensor tests already run the same capture.
"""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "viform._validate",
    "viform.light.radiometry",
    "viform.light.catalog",
    "viform.sensors.catalog",
    "viform.sensors.overflow",
    "viform.sensors.subthreshold",
    "viform.stream.sidecar",
    "viform.coding.first_spike",
    "viform.isp.histogram",
    "viform.isp.link",
    "viform.measure.dynamic_range",
]


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, report=True)
    assert result.attempted > 0, f"{name} has no examples: take it off the list or give it one"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples fail (printed above)"
