"""The package's imports flow one way: read from the source (imports inside functions included),
no module imports one from a higher layer, and no modules import each other in a circle.

Layers, lowest first (README, docs/CONTRIBUTING.md)::

    _validate, _lazy → _io, _parallel, _worker_preload → light → stream → sensors → coding, imaging, isp, display
    → vision → datasets → measure → report → cli

Modules of one layer may import each other (a module of ``imaging`` one of ``coding``), as
long as no circle forms. A circle found while its split is under way may be listed in
:data:`KNOWN_CIRCLES` (none is now).
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "viform"

#: Groups of the package (first part of the module name below ``viform``), lowest layer first.
LAYERS = (
    ("_validate", "_lazy"),
    ("_io", "_parallel", "_worker_preload"),
    ("light",),
    ("stream",),
    ("sensors",),
    ("coding", "imaging", "isp", "display"),
    ("vision",),
    ("datasets", "torch", "torch_dataset"),
    ("measure",),
    ("report",),
    ("cli", "__main__"),
)
#: The top-level package (``viform/__init__.py``) sits below everything: it may import nothing of the package
#: that would import it back.
TOP = "viform"
#: Modules below the top-level package itself, which it may import: they import nothing of the package
#: (``_numba_cache``, installed on import when ``VIFORM_SHARE_COMPILES=1``).
BELOW_TOP = ("_numba_cache",)

#: Circles known to be in the code, by the work that removes them, with the modules that form them
#: (none now: the spike kernels and the scene catalogue have their own modules).
KNOWN_CIRCLES: dict[str, set[str]] = {}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


@functools.cache
def imports() -> frozenset[tuple[str, str, int]]:
    """(importer, imported module, line) of every in-package import, at any depth of the source."""
    mods = _modules()
    found = set()
    for me, path in mods.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = me.split(".") if is_package else me.split(".")[:-1]
                    base = base[: len(base) - node.level + 1]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                # "from viform.x import y" imports the module viform.x.y when there is one
                targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in mods else module for a in node.names]
            else:
                continue
            for target in targets:
                if target.split(".")[0] == TOP and target != me:
                    found.add((me, target, node.lineno))
    return frozenset(found)


def layer_of(module: str) -> int:
    if module == TOP:
        return -1
    group = module.split(".")[1]
    if group in BELOW_TOP:
        return -2
    for i, layer in enumerate(LAYERS):
        if group in layer:
            return i
    raise AssertionError(f"module {module} is in no layer: add its group {group!r} to LAYERS")


@functools.cache
def circles() -> tuple[frozenset[str], ...]:
    """The strongly connected components of more than one module of the import graph (Tarjan)."""
    graph: dict[str, set[str]] = {m: set() for m in _modules()}
    for a, b, _ in imports():
        if b in graph:
            graph[a].add(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[frozenset[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(frozenset(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return tuple(out)


def test_every_module_has_a_layer():
    for module in _modules():
        layer_of(module)


def test_no_import_points_up():
    """An import from a lower layer to a higher one (e.g. a sensor importing measure) is refused."""
    up = sorted(f"{a} imports {b} (line {line}): layer {LAYERS[layer_of(a)]} below {LAYERS[layer_of(b)]}"
                for a, b, line in imports() if layer_of(b) > layer_of(a))
    assert not up, "\n".join(up)


def test_no_circle_but_the_known_ones():
    unknown = [c for c in circles() if not any(known <= c for known in KNOWN_CIRCLES.values())]
    assert not unknown, "import circles: " + "; ".join(" <-> ".join(sorted(c)) for c in unknown)


def test_the_reader_sees_function_level_imports():
    """The check reads imports inside functions too (most circles hide there)."""
    found = {(a, b) for a, b, _ in imports()}
    # cli.app imports its commands inside a function: those edges are seen
    assert any(a.startswith("viform.cli") and b.startswith("viform.measure") for a, b in found)
    assert layer_of("viform.sensors.spike") < layer_of("viform.measure.sweep")
