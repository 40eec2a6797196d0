"""Storage: the history of units, tests, estimates, baselines, symptoms, diagnoses."""

from condmon.store.db import (
    DuplicateTestError, HistoryStore, StoredTest, StoreError, file_hash, frame_hash, open_store,
)
from condmon.store.schema import SCHEMA_VERSION

__all__ = ["HistoryStore", "open_store", "file_hash", "frame_hash", "DuplicateTestError",
           "StoreError", "StoredTest", "SCHEMA_VERSION"]
