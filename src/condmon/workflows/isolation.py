"""An isolation kept in a unit's history (``condmon isolate ... --unit U --db DB``)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from condmon.diagnose.isolation import IsolationResult
from condmon.errors import DataError
from condmon.io.columns import Columns
from condmon.models.registry import get_model
from condmon.store.db import DuplicateTestError, HistoryStore
from condmon.workflows.monitoring import record_key

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["StoredIsolation", "store_isolation"]


@dataclass(frozen=True)
class StoredIsolation:
    """Where an isolation went in the history.

    Attributes
    ----------
    unit : str
    isolation_id : int
        Its id (the existing one for a duplicate).
    duplicate : bool
        The record was already among the unit's isolations (nothing written).
    test_date : datetime or None
        When the test was run, if known (UTC).
    warning : str or None
        The same record is also an isolation of another unit (a mix-up of
        serial numbers or folders?).
    """

    unit: str
    isolation_id: int
    duplicate: bool
    test_date: datetime | None
    warning: str | None = None


def store_isolation(store: HistoryStore, unit: str, result: IsolationResult,
                    record: pd.DataFrame | Columns, path: str | Path | None, model: str,
                    test_date: str | datetime | None = None) -> StoredIsolation:
    """Store one isolation of ``record`` (read from ``path``) for ``unit``.

    ``model`` is the plant model's name or declaration file; a unit keeps the
    model its history was started with, and a record offered with another is
    refused. The same content twice is recognised (not stored again).

    Raises
    ------
    DataError
        The unit is monitored with another model.
    """
    machine = get_model(model)
    stored = store.unit_model(unit)
    if stored is not None and stored not in (machine.name, machine.origin):
        raise DataError(f"unit {unit!r} is monitored with model {stored!r}; this record was "
                        f"isolated with {model!r}")
    key = record_key(record, path, test_date)
    source = str(path) if path is not None else str(record.attrs.get("source", "record"))
    try:
        iid = store.add_isolation(unit, result, model=machine.name, source=source,
                                  digest=key.content, file_digest=key.file, fingerprint=key.fingerprint,
                                  test_date=key.test_date, model_source=machine.origin)
    except DuplicateTestError as dup:
        return StoredIsolation(unit, dup.test_id, True, key.test_date)
    others = store.isolation_copies_elsewhere(unit, key.content)
    where = ", ".join(f"isolation i{i} of {u!r}" for u, i in others[:3])
    return StoredIsolation(unit, iid, False, key.test_date,
                           f"the same record is also {where}; is it filed under the right "
                           "unit?" if others else None)
