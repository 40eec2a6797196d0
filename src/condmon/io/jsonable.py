"""Values and tables as JSON: what ``--json`` prints and the web API returns."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from datetime import datetime
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pandas is not imported for a value: `condmon --help` prints JSON helpers
    import pandas as pd

__all__ = ["json_safe", "frame_records", "JSON_TEXT_COLUMNS"]

#: Table columns the history keeps as JSON text; :func:`frame_records` gives
#: their values as JSON (an object or a list), not as a string.
JSON_TEXT_COLUMNS = ("fits", "detail", "suspects", "isolated", "test_ids", "flags")


def json_safe(value: Any) -> Any:
    """``value`` with only JSON types (recursively): non-finite numbers as None,
    numpy scalars and arrays as numbers and lists, dates as ISO 8601 text (UTC
    as ``Z``), anything else unknown as its text. Floats keep every digit.

    Example
    -------
    >>> import numpy as np
    >>> json_safe({"a": float("inf"), "b": [np.float64(1.5), np.nan], "c": (1, 2)})
    {'a': None, 'b': [1.5, None], 'c': [1, 2]}
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if type(value).__name__ == "NAType":  # pandas' missing value, without importing pandas
        return None
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [json_safe(v) for v in value]
    if isinstance(value, datetime):  # pandas' Timestamp and NaT too
        if value != value:  # NaT
            return None
        text = value.isoformat()
        return text[:-6] + "Z" if text.endswith("+00:00") else text
    tolist = getattr(value, "tolist", None)  # numpy scalars and arrays
    if callable(tolist):
        try:
            return json_safe(tolist())
        except Exception:  # noqa: BLE001 - fall back to the text
            return str(value)
    return str(value)


def frame_records(frame: pd.DataFrame,
                  json_columns: Iterable[str] = JSON_TEXT_COLUMNS) -> list[dict[str, Any]]:
    """A table's rows (its index as the first column) as JSON-ready dicts:
    floats with every digit, NaN as None, dates in ISO 8601, ids (``id``,
    ``*_id``) as integers, and the columns held as JSON text (``fits``,
    ``detail``, ...) as JSON values.

    Example
    -------
    >>> import pandas as pd
    >>> df = pd.DataFrame({"R": [1.0000000001, float("nan")], "fits": ['{"I": 93.5}', None]},
    ...                   index=pd.Index([1, 2], name="test_id"))
    >>> frame_records(df)
    [{'test_id': 1, 'R': 1.0000000001, 'fits': {'I': 93.5}}, {'test_id': 2, 'R': None, 'fits': None}]
    """
    as_json = set(json_columns)
    rows = []
    for row in frame.reset_index().to_dict(orient="records"):
        doc = {}
        for key, value in row.items():
            if str(key) in as_json and isinstance(value, str):
                try:
                    value = json.loads(value)
                except ValueError:
                    pass  # not JSON after all: kept as text
            if (str(key) == "id" or str(key).endswith("_id")) and isinstance(value, float) \
                    and value.is_integer():
                value = int(value)  # an id column with gaps is float in pandas
            doc[str(key)] = json_safe(value)
        rows.append(doc)
    return rows
