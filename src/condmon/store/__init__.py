"""Storage: the history of units, tests, estimates, baselines, evaluations, isolations, audit."""

from condmon.store.baselines import DEFAULT_BASELINE, StoredBaseline
from condmon.store.db import HistoryStore, file_hash, frame_hash, open_store
from condmon.store.engine import StoreBusyError, StoreError
from condmon.store.history import DuplicateTestError, TestInfo
from condmon.store.isolations import isolation_status
from condmon.store.schema import SCHEMA_VERSION
from condmon.store.views import test_status

__all__ = ["HistoryStore", "open_store", "file_hash", "frame_hash", "DuplicateTestError",
           "StoreError", "StoreBusyError", "StoredBaseline", "DEFAULT_BASELINE", "TestInfo",
           "SCHEMA_VERSION", "isolation_status", "test_status"]
