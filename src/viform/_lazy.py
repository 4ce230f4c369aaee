"""Lazy public names for a subpackage's ``__init__`` (PEP 562), as scikit-image's ``lazy_loader`` does.

A subpackage lists its public names in ``__all__`` and, for each submodule, the names it defines;
:func:`attach` returns the module's ``__getattr__`` and ``__dir__``. ``import viform.sensors``
then imports nothing more: the submodule holding a name (and NumPy, Numba, SciPy ... behind it) is
imported when the name is first used, and the name is kept in the package's namespace from then on.
A command that imports ``viform.sensors.spike`` pays for that module only, not for the whole
subpackage.
"""

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping


def attach(package: str, public: Iterable[str], submodules: Mapping[str, Iterable[str]]
           ) -> "tuple[Callable[[str], object], Callable[[], list[str]]]":
    """The ``__getattr__`` and ``__dir__`` of ``package`` that import each public name on first use.

    Parameters
    ----------
    package : str
        The subpackage's ``__name__`` (``"viform.sensors"``).
    public : iterable of str
        Its ``__all__``: every public name, each defined by exactly one entry of ``submodules``.
    submodules : mapping of str to iterable of str
        Submodule name relative to ``package`` (``"spike"``, ``"sweep.plan"``) → the public names it
        defines.

    Returns
    -------
    __getattr__ : callable
        ``name → object``: imports the submodule defining ``name`` and returns (and keeps) the object;
        an unknown name raises ``AttributeError`` (so ``from package import submodule`` still works).
    __dir__ : callable
        The public names and whatever the package's namespace already holds that is not private.

    Raises
    ------
    ValueError
        When ``public`` and the names of ``submodules`` differ (a name listed twice, or only in one).
    """
    where = {name: module for module, names in submodules.items() for name in names}
    listed = sum(len(tuple(names)) for names in submodules.values())
    public = list(public)
    if set(where) != set(public) or listed != len(where) or len(set(public)) != len(public):
        raise ValueError(f"{package}: __all__ and the submodule table differ: only in __all__ "
                         f"{sorted(set(public) - set(where))}, only in the table {sorted(set(where) - set(public))}, "
                         "or a name listed twice")

    def __getattr__(name: str) -> object:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        present = (n for n in vars(sys.modules[package]) if not n.startswith("_"))
        return sorted(set(public).union(present))

    return __getattr__, __dir__
