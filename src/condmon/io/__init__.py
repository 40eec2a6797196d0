"""Input/output: reading records (CSV, text, Parquet, MATLAB, TDMS), validating them,
configuration files."""

from condmon.io.config import load_default, load_toml, merge
from condmon.io.readers import READABLE_SUFFIXES, read_record
from condmon.io.records import (
    Record, check_time_base, parse_column_map, validate_record, write_record,
)

__all__ = ["Record", "read_record", "validate_record", "check_time_base", "write_record",
           "parse_column_map", "READABLE_SUFFIXES", "load_toml", "load_default", "merge"]
