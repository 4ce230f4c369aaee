"""Each subpackage's ``__init__`` is its public API: the names of ``__all__`` resolve, are public, come
from inside the subpackage, show in ``dir()``, and (for the lazy ones) cost nothing to import until used.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import pkgutil
import subprocess
import sys

import pytest

from viform import _lazy

#: Subpackages whose ``__init__`` imports names on first use (viform._lazy).
LAZY = ["light", "sensors", "stream", "coding", "isp", "vision", "measure"]
#: Subpackages with an API, lazy or not.
API = LAZY + ["imaging", "datasets"]
#: What importing a lazy subpackage must not import.
HEAVY = ["numpy", "numba", "scipy", "matplotlib"]
#: What a subpackage's own import needs beyond its ``__init__``, and why. ``viform.coding`` installs numba's
#: cache locators before any of its kernels is defined (viform.coding._compile_cache), so it imports numba
#: (which brings NumPy and SciPy).
ALSO = {"coding": ["viform.coding._compile_cache", "numba", "numpy", "scipy"]}


def _package(name: str):
    return importlib.import_module(f"viform.{name}")


@pytest.mark.parametrize("name", API)
def test_every_exported_name_resolves_from_inside_the_subpackage(name):
    package = _package(name)
    assert package.__all__, f"viform.{name} exports nothing"
    assert len(set(package.__all__)) == len(package.__all__), f"viform.{name}.__all__ lists a name twice"
    for public in package.__all__:
        assert not public.startswith("_"), f"viform.{name} exports the private name {public}"
        obj = getattr(package, public)
        home = getattr(obj, "__module__", None)
        if home is None:  # a constant (a dict, a tuple ...): it must be the one of a submodule
            home = next(m.__name__ for m in list(sys.modules.values())
                        if getattr(m, "__name__", "").startswith(f"viform.{name}.") and getattr(m, public, None) is obj)
        assert home.startswith(f"viform.{name}."), f"viform.{name}.{public} comes from {home}"


@pytest.mark.parametrize("name", API)
def test_dir_lists_the_public_names(name):
    package = _package(name)
    listed = dir(package)
    assert set(package.__all__) <= set(listed)
    assert listed == sorted(listed)


@pytest.mark.parametrize("name", API)
def test_no_exported_name_hides_a_submodule(name):
    """A submodule, once imported, becomes an attribute of its package: an exported name equal to a
    submodule's would be replaced by the module."""
    package = _package(name)
    submodules = {m.name for m in pkgutil.iter_modules(package.__path__)}
    assert not set(package.__all__) & submodules


@pytest.mark.parametrize("name", LAZY)
def test_importing_a_subpackage_imports_nothing_heavy(name):
    """In a fresh interpreter, ``import viform.NAME`` imports none of its submodules nor NumPy, Numba,
    SciPy or matplotlib (but what :data:`ALSO` says); the first use of a name imports its submodule."""
    package = _package(name)
    first = package.__all__[0]
    code = (
        "import sys, json\n"
        f"import viform.{name} as p\n"
        f"before = sorted(m for m in sys.modules if m.split('.')[0] == 'viform' or m in {HEAVY!r})\n"
        f"getattr(p, {first!r})\n"
        f"after = sorted(m for m in sys.modules if m.startswith('viform.{name}.'))\n"
        "print(json.dumps([before, after]))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "VIFORM_SHARE_COMPILES"}  # a user's plain import
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    before, after = json.loads(out)
    expected = sorted(["viform", "viform._lazy", f"viform.{name}", *ALSO.get(name, [])])
    assert before == expected, f"import viform.{name} imported {before}"
    home = getattr(package, first).__module__
    assert home in after, f"using {first} did not import {home}: {after}"


@pytest.mark.parametrize("name", LAZY)
def test_star_import_and_unknown_names(name):
    namespace: dict = {}
    exec(f"from viform.{name} import *", namespace)
    assert set(_package(name).__all__) <= set(namespace)
    with pytest.raises(AttributeError, match="no_such_name"):
        _package(name).no_such_name  # noqa: B018


def test_a_submodule_is_still_reachable_by_from_import():
    from viform.sensors import spike

    assert inspect.ismodule(spike) and spike.__name__ == "viform.sensors.spike"


def test_attach_refuses_a_table_that_differs_from_all():
    with pytest.raises(ValueError, match="only in __all__ \\['b'\\]"):
        _lazy.attach("viform.sensors", ["a", "b"], {"base": ["a"]})
    with pytest.raises(ValueError, match="listed twice"):
        _lazy.attach("viform.sensors", ["a"], {"base": ["a"], "spike": ["a"]})


def _section(doc: str, title: str) -> list[str] | None:
    """The lines of numpydoc section ``title`` of a cleaned docstring, None when it has none."""
    lines = doc.splitlines() + [""]

    def header(i: int) -> bool:
        return bool(lines[i]) and not lines[i].startswith(" ") and i + 1 < len(lines) \
            and set(lines[i + 1]) == {"-"} and len(lines[i + 1]) == len(lines[i])

    for i in range(len(lines)):
        if lines[i] == title and header(i):
            end = next((j for j in range(i + 2, len(lines)) if header(j)), len(lines))
            return lines[i + 2:end]
    return None


def _documented(section: list[str]) -> set[str]:
    """Parameter names of a Parameters section: ``a, b : type`` or ``*args`` lines at its left margin."""
    names = set()
    for line in section:
        if line and not line.startswith(" "):
            names |= {n.strip().lstrip("*") for n in line.split(" : ")[0].split(",")}
    return names


@pytest.mark.parametrize("name", LAZY)
def test_exported_functions_carry_numpydoc_parameters_and_returns(name):
    """Every public function a subpackage exports documents each parameter (its unit in its text) and
    what it returns (or yields), in numpydoc sections."""
    package = _package(name)
    for public in package.__all__:
        obj = getattr(package, public)
        if not inspect.isfunction(obj):
            continue
        doc = inspect.cleandoc(obj.__doc__ or "")
        where = f"{obj.__module__}.{public}"
        parameters = [p for p in inspect.signature(obj).parameters]
        if parameters:
            section = _section(doc, "Parameters")
            assert section is not None, f"{where}: no Parameters section"
            missing = set(parameters) - _documented(section)
            assert not missing, f"{where}: parameters {sorted(missing)} not in its Parameters section"
        assert _section(doc, "Returns") or _section(doc, "Yields"), f"{where}: no Returns (or Yields) section"



#: A process that imports viform (and with "cli", runs a command: ``viform --help``), then runs its first
#: numba parallel kernel, which loads the OpenMP runtime.
_FIRST_PARALLEL_KERNEL = (
    "import os, sys, numba, numpy as np, viform\n"
    "if sys.argv[1] == 'cli':\n"
    "    from viform.cli import main\n"
    "    assert main(['--help']) == 0\n"
    "@numba.njit(parallel=True)\n"
    "def total(a):\n"
    "    s = 0.0\n"
    "    for i in numba.prange(a.size):\n"
    "        s += a[i]\n"
    "    return s\n"
    "assert total(np.ones(64)) == 64.0\n"
    "print(os.environ.get('OMP_WAIT_POLICY', '-'), numba.threading_layer(), file=sys.stderr)\n"
)


@pytest.mark.parametrize(("run", "chosen", "expected"), [("import", None, "-"), ("cli", None, "PASSIVE"),
                                                        ("cli", "ACTIVE", "ACTIVE")])
def test_the_command_line_lets_openmp_threads_wait_passively_unless_the_user_chose(run, chosen, expected):
    """A command makes numba's OpenMP threads sleep between parallel regions (not spin), unless the user set a
    wait policy; importing the library leaves the environment alone (other OpenMP users in the process, such
    as PyTorch, keep their default). GNU libgomp says what it read (OMP_DISPLAY_ENV)."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    env["OMP_DISPLAY_ENV"] = "VERBOSE"
    if chosen is not None:
        env["OMP_WAIT_POLICY"] = chosen
    done = subprocess.run([sys.executable, "-c", _FIRST_PARALLEL_KERNEL, run], capture_output=True, text=True,
                          check=True, env=env)
    policy, layer = done.stderr.strip().splitlines()[-1].split()
    assert policy == expected
    if layer == "omp" and "GOMP_SPINCOUNT" in done.stderr:  # the runtime read it when it loaded
        assert ("GOMP_SPINCOUNT = '0'" in done.stderr) == (expected == "PASSIVE"), done.stderr
