"""Consoles and small output helpers shared by the command modules."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["out", "err", "fmt", "write_json", "json_safe", "progress"]

out = Console()
err = Console(stderr=True)


def fmt(value: float) -> str:
    """A number with 5 significant digits."""
    return f"{value:.5g}"


def write_json(doc: Any) -> None:
    """Print ``doc`` as JSON. Never raises on the content: a non-finite number
    (NaN, ±inf) becomes null, numpy scalars and arrays become numbers and lists,
    anything else unknown its text."""
    sys.stdout.write(json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")


def json_safe(value: Any) -> Any:
    """``value`` with only JSON types, non-finite numbers as None (recursively).

    Example
    -------
    >>> import numpy as np
    >>> json_safe({"a": float("inf"), "b": [np.float64(1.5), np.nan], "c": (1, 2)})
    {'a': None, 'b': [1.5, None], 'c': [1, 2]}
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [json_safe(v) for v in value]
    tolist = getattr(value, "tolist", None)  # numpy scalars and arrays
    if callable(tolist):
        try:
            return json_safe(tolist())
        except Exception:  # noqa: BLE001 - fall back to the text
            return str(value)
    return str(value)


def progress() -> Progress:
    """A progress bar on stderr that disappears when done."""
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err, transient=True)
