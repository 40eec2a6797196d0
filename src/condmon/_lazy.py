"""Lazy re-exports for the package ``__init__`` files (PEP 562).

A package names what it re-exports and where each name lives; the defining
module is imported on first access of the name, not when the package is. So
``import condmon.cli.main`` does not pay for scipy, sympy or pandas until a
command needs them.

Example
-------
In a package's ``__init__.py``::

    _EXPORTS = {"estimate": "condmon.identify.estimate"}

    def __getattr__(name: str) -> Any:
        return load(__name__, _EXPORTS, name)
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["load", "names", "shield"]


def load(package: str, exports: Mapping[str, str], name: str) -> Any:
    """The object ``name`` re-exported by ``package``, imported now and kept in
    the package's namespace; :class:`AttributeError` for a name not re-exported."""
    where = exports.get(name)
    if where is None:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(where), name)
    vars(sys.modules[package])[name] = value  # later look-ups skip __getattr__
    return value


def names(namespace: Mapping[str, Any], exports: Mapping[str, str]) -> list[str]:
    """``dir()`` of a package with lazy re-exports: its ``__all__`` (when it
    has one; not its helpers such as ``TYPE_CHECKING`` or ``annotations``),
    the re-exports, the submodules imported so far and its dunder names."""
    listed = namespace.get("__all__")
    if listed is None:
        return sorted({*namespace, *exports})
    modules = {n for n, v in namespace.items() if isinstance(v, types.ModuleType)}
    return sorted({*listed, *exports, *modules, *(n for n in namespace if n.startswith("__"))})


class _Shielded(types.ModuleType):
    """A package whose re-exported functions keep their names when a submodule
    of the same name is imported (``condmon.identify.estimate`` is the function
    ``estimate``, as it was when the package imported it eagerly)."""

    _shielded: frozenset[str] = frozenset()

    def __setattr__(self, name: str, value: Any) -> None:
        if name in type(self)._shielded and isinstance(value, types.ModuleType):
            return  # the import system binding the submodule: keep the function
        super().__setattr__(name, value)


def shield(package: str, shadowed: Iterable[str]) -> None:
    """Keep ``shadowed`` (names both of a re-exported object and of a submodule)
    bound to the re-exported object in ``package``."""
    module = sys.modules[package]
    cls = type(f"_Shielded_{package.replace('.', '_')}", (_Shielded,),
               {"_shielded": frozenset(shadowed)})
    module.__class__ = cls
