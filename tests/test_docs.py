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
