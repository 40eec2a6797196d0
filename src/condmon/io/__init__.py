"""Input/output: reading and validating records, configuration files."""

from condmon.io.config import load_default, load_toml, merge
from condmon.io.records import (
    Record, parse_column_map, read_record, validate_record, write_record,
)

__all__ = ["Record", "read_record", "validate_record", "write_record", "parse_column_map",
           "load_toml", "load_default", "merge"]
