"""Loading the TOML files that hold domain knowledge (plant parameters, rules, ...).

Shipped defaults live in ``condmon/data``; a user passes an edited copy. Values
in a user file override the defaults key by key, so a file may hold only what it
changes.
"""

from __future__ import annotations

import dataclasses
import functools
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from condmon.errors import ConfigError

__all__ = ["load_toml", "load_default", "merge", "shipped_limits"]

T = TypeVar("T")


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file, raising :class:`ConfigError` naming the file on failure.

    Example
    -------
    >>> cfg = load_default("actuator.toml")
    >>> cfg["motor"]["R"]
    1.0
    """
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{p}: file not found") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: not valid TOML: {err}") from None
    except UnicodeDecodeError as err:
        raise ConfigError(f"{p}: not valid TOML (not UTF-8 text: {err.reason})") from None
    except OSError as err:  # a folder, no permission, ...
        raise ConfigError(f"{p}: cannot read: {err.strerror or err}") from None


def load_default(name: str) -> dict[str, Any]:
    """Read a TOML file shipped in ``condmon/data``."""
    ref = resources.files("condmon") / "data" / name
    with ref.open("rb") as fh:
        return tomllib.load(fh)


@functools.lru_cache(maxsize=None)
def _limits_table(section: str) -> tuple[tuple[str, Any], ...]:
    return tuple(load_default("limits.toml").get(section, {}).items())


def shipped_limits(section: str, cls: type[T]) -> T:
    """One table of the shipped ``condmon/data/limits.toml`` as ``cls``, a frozen
    dataclass whose fields carry their defaults: a key the table sets overrides
    its field (cast to the default's type), an unknown key is refused.

    Example
    -------
    >>> from condmon.io.size import RecordLimits
    >>> shipped_limits("records", RecordLimits).max_bytes
    1000000000
    """
    table = dict(_limits_table(section))
    fields: dict[str, Any] = {f.name: f.default
                              for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise ConfigError(f"condmon/data/limits.toml: [{section}] has no {unknown[0]!r}; "
                          f"allowed: {', '.join(fields)}")
    try:
        return cls(**{k: type(fields[k])(v) for k, v in table.items()})
    except (TypeError, ValueError):
        raise ConfigError(f"condmon/data/limits.toml: [{section}] holds a value that is not "
                          "a number") from None


def merge(base: dict[str, Any], override: dict[str, Any], source: str = "") -> dict[str, Any]:
    """Recursive key-by-key override of ``base`` by ``override``.

    Keys of ``override`` that ``base`` does not know are refused (a typo in a
    parameter file must not pass silently).
    """
    out = dict(base)
    for key, value in override.items():
        if key not in base:
            allowed = ", ".join(sorted(base))
            where = f"{source}: " if source else ""
            raise ConfigError(f"{where}unknown key {key!r}; allowed: {allowed}")
        if isinstance(base[key], dict):
            if not isinstance(value, dict):
                raise ConfigError(f"{source}: [{key}] must be a table")
            out[key] = merge(base[key], value, f"{source}[{key}]" if source else f"[{key}]")
        else:
            out[key] = value
    return out
