"""A small on-disk cache of what condmon derives symbolically from a declaration.

Deriving a model's structure (transfer functions and their coefficient map,
the simulator's right-hand side, residual generators, the fault signature
matrix) takes sympy and, for the structural analysis, the Fault Diagnosis
Toolbox: about a second of imports and work, every run, for a result that
depends only on the declaration's equations. The cache keeps that result per
declaration, so a command on an unchanged declaration needs neither.

- **Key**: a SHA-256 of the equations' content (names, equations, fault
  flags, smoothing; not the file's path nor the parameters' values), the source
  of the modules that derive, numpy's version and :data:`FORMAT`. Editing a
  declaration or upgrading condmon gives a new key; nothing goes stale silently.
- **Content**: one JSON file per key, one entry per derived item. Functions
  are kept as the Python source sympy generated for them (``lambdify``) with the
  numpy names it uses, checked when written to give the same values as the
  derived function.
- **Robust**: a cache that cannot be read, written or understood is ignored
  and the structure derived as before; nothing is raised, nothing printed. Only
  successful derivations are kept (an invalid declaration is re-read and its
  error reported every time).
- **Where**: ``$CONDMON_CACHE_DIR``, else ``$XDG_CACHE_HOME/condmon`` or
  ``~/.cache/condmon`` (``%LOCALAPPDATA%\\condmon`` on Windows). Set
  ``CONDMON_NO_CACHE=1`` to derive every time.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import inspect
import json
import os
import tempfile
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:
    from condmon.models.declared import PlantModel

__all__ = ["FORMAT", "cache_dir", "plant_key", "cached", "portable", "restore_function"]

#: Version of the cache's layout; a change makes every earlier entry unused.
FORMAT = 1

T = TypeVar("T")

# The modules whose code decides what is derived: a change to any gives new keys.
_DERIVING = ("models/declared.py", "models/machine.py", "models/expressions.py",
             "models/derived_cache.py", "diagnose/structure.py")

# Where the names a generated function uses may come from.
_MODULES = ("numpy", "numpy.linalg", "functools", "math", "cmath", "builtins")

_DOCS: dict[str, dict[str, Any]] = {}


def cache_dir() -> Path | None:
    """The cache folder, or None when caching is switched off."""
    if os.environ.get("CONDMON_NO_CACHE"):
        return None
    given = os.environ.get("CONDMON_CACHE_DIR")
    if given:
        return Path(given)
    if os.name == "nt" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "condmon"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "condmon"


@functools.lru_cache(maxsize=1)
def _code_digest() -> str | None:
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    try:
        for rel in _DERIVING:
            h.update(rel.encode() + b"\0" + (root / rel).read_bytes())
    except OSError:
        return None  # no source to tell versions apart: no cache
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def plant_key(model: PlantModel) -> str | None:
    """The cache key of a plant model's equations (None: no caching)."""
    code = _code_digest()
    if code is None:
        return None
    doc = {
        "parameters": [[p.name, p.fault] for p in model.parameters],
        "inputs": list(model.input_names),
        "variables": [[v.name, v.equation] for v in model.variables],
        "states": [[s.name, s.derivative] for s in model.states],
        "sensors": [[s.name, s.measures] for s in model.sensors],
        "smoothing": model.smoothing,
    }
    text = json.dumps([FORMAT, code, np.__version__, doc], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _read(key: str) -> dict[str, Any]:
    if key in _DOCS:
        return _DOCS[key]
    doc: dict[str, Any] = {}
    folder = cache_dir()
    if folder is not None:
        try:
            loaded = json.loads((folder / f"{key}.json").read_text(encoding="utf-8"))
            if isinstance(loaded, dict) and loaded.get("format") == FORMAT \
                    and isinstance(loaded.get("items"), dict):
                doc = loaded["items"]
        except (OSError, ValueError, UnicodeDecodeError):
            pass
    _DOCS[key] = doc
    return doc


def _write(key: str, name: str, data: Any) -> None:
    doc = _read(key)
    doc[name] = data
    folder = cache_dir()
    if folder is None:
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{key[:16]}-", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                json.dump({"format": FORMAT, "items": doc}, fh)
            os.replace(tmp, folder / f"{key}.json")  # readers see the old or the new file
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    except (OSError, TypeError, ValueError):
        pass  # a read-only or full disk: derive again next time


def cached(key: str | None, name: str, derive: Callable[[], T],
           dump: Callable[[T], Any], restore: Callable[[Any], T]) -> T:
    """Item ``name`` of the declaration with ``key``: restored from the cache, or
    derived (and then stored when ``dump`` gives JSON-ready data, not None)."""
    if key is None:
        return derive()
    doc = _read(key)
    if name in doc:
        try:
            return restore(doc[name])
        except Exception:  # noqa: BLE001 - an entry this code cannot use: derive
            doc.pop(name, None)
    value = derive()
    try:
        data = dump(value)
    except Exception:  # noqa: BLE001 - not storable: derived again next time
        data = None
    if data is not None:
        _write(key, name, data)
    return value


def _global_names(code: types.CodeType) -> Iterator[str]:
    yield from code.co_names
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            yield from _global_names(const)


def portable(fn: Callable[..., Any], *probe: Any) -> dict[str, Any] | None:
    """A function generated by ``sympy.lambdify`` as JSON-ready data (its source
    and where each global name it uses comes from), or None when it cannot be
    kept or, restored, does not give the same value as ``fn`` on ``probe``."""
    try:
        source = inspect.getsource(fn)
    except (OSError, TypeError):
        return None
    where: dict[str, list[str]] = {}
    for name in set(_global_names(fn.__code__)):
        if name not in fn.__globals__:
            continue  # a builtin, or an attribute name
        value = fn.__globals__[name]
        if isinstance(value, types.ModuleType):
            if value.__name__ not in _MODULES:
                return None
            where[name] = [value.__name__, ""]
            continue
        module = next((m for m in _MODULES
                       if getattr(_module(m), name, None) is value), None)
        if module is None:
            return None
        where[name] = [module, name]
    data = {"source": source, "name": fn.__name__, "globals": where}
    with np.errstate(all="ignore"):
        if not _same(fn(*probe), restore_function(data)(*probe)):
            return None
    return data


def _module(name: str) -> types.ModuleType:
    return importlib.import_module(name)


def restore_function(data: dict[str, Any]) -> Callable[..., Any]:
    """The function kept by :func:`portable`."""
    namespace: dict[str, Any] = {}
    for name, (module, attr) in data["globals"].items():
        if module not in _MODULES:
            raise ValueError(f"unexpected module {module!r}")
        mod = _module(module)
        namespace[name] = getattr(mod, attr) if attr else mod
    exec(compile(data["source"], "<condmon cached model>", "exec"), namespace)  # noqa: S102
    fn = namespace[data["name"]]
    if not callable(fn):
        raise TypeError("not a function")
    return fn  # type: ignore[no-any-return]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
        return (isinstance(a, (list, tuple)) and isinstance(b, (list, tuple))
                and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b)))
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    return x.shape == y.shape and bool(np.array_equal(x, y, equal_nan=True))
