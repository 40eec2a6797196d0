"""Input/output: reading records (CSV, text, Parquet, MATLAB, TDMS), validating them,
configuration files."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from condmon._lazy import load, names

if TYPE_CHECKING:
    from condmon.io.config import load_default, load_toml, merge
    from condmon.io.readers import READABLE_SUFFIXES, read_record
    from condmon.io.records import (
        Record, check_time_base, parse_column_map, validate_record, write_record,
    )

__all__ = ["Record", "read_record", "validate_record", "check_time_base", "write_record",
           "parse_column_map", "READABLE_SUFFIXES", "load_toml", "load_default", "merge"]

# Imported on first use (PEP 562).
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("load_default", "load_toml", "merge"), "condmon.io.config"),
    **dict.fromkeys(("READABLE_SUFFIXES", "read_record"), "condmon.io.readers"),
    **dict.fromkeys(("Record", "check_time_base", "parse_column_map", "validate_record",
                     "write_record"),
                    "condmon.io.records"),
}


def __getattr__(name: str) -> Any:
    return load(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return names(globals(), _EXPORTS)
