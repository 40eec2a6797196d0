"""Every public module's docstring examples run, and public callables are documented."""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil

import pytest

import condmon

MODULES = sorted(m.name for m in pkgutil.walk_packages(condmon.__path__, "condmon."))


@pytest.mark.parametrize("name", MODULES)
def test_doctests(name: str) -> None:
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0


@pytest.mark.parametrize("name", MODULES)
def test_public_api_is_documented(name: str) -> None:
    module = importlib.import_module(name)
    for attr in getattr(module, "__all__", []):
        obj = getattr(module, attr)
        if inspect.isfunction(obj) or inspect.isclass(obj):
            assert obj.__doc__, f"{name}.{attr} has no docstring"


def test_a_notebook_sees_the_public_api_at_the_top_not_the_module_s_helpers() -> None:
    """dir(condmon) listed Any, TYPE_CHECKING, annotations, load and names."""
    shown = {n for n in dir(condmon) if not n.startswith("_")}
    assert set(condmon.__all__) - {"__version__"} <= shown
    assert not shown & {"Any", "TYPE_CHECKING", "annotations", "load", "names"}
    for name in ("condmon.identify", "condmon.monitor", "condmon.forecast"):
        package = importlib.import_module(name)
        assert set(getattr(package, "__all__", ())) <= set(dir(package)), name
        assert "TYPE_CHECKING" not in dir(package) and "annotations" not in dir(package)
