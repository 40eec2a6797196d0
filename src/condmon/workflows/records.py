"""One record as the workflows know it: read, estimated, and keyed for the
history (content hash, file hash, test date). Nothing here touches the store, so
``condmon estimate`` and a fleet worker pay for no database import."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import pandas as pd

from condmon.identify.estimate import EstimateResult, estimate
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD
from condmon.io.dates import parse_date
from condmon.io.digest import content_hash, file_hash, fingerprint
from condmon.io.records import read_record

__all__ = ["EstimateOptions", "RecordKey", "RecordLike", "record_key"]

RecordLike = str | Path | pd.DataFrame


@dataclass(frozen=True)
class RecordKey:
    """How a record is known in the history.

    Attributes
    ----------
    content : str
        Content hash (:func:`condmon.io.digest.content_hash`): the same data in
        another file, format or line-end convention is the same test.
    file : str
        SHA-256 of the file's bytes (of the content for an in-memory record).
    test_date : datetime or None
        When the test was run (UTC): given, else read from the record's
        metadata (a date-time time column, a TDMS start time), else unknown.
    fingerprint : str or None
        A few figures per column (:func:`condmon.io.digest.fingerprint`): a
        copy rounded otherwise or with a column more or fewer is the same test.
    """

    content: str
    file: str
    test_date: datetime | None
    fingerprint: str | None = None


def record_key(df: pd.DataFrame, path: str | Path | None = None,
               test_date: str | datetime | None = None) -> RecordKey:
    """The :class:`RecordKey` of a parsed record (``path``: its file, if any)."""
    digest = content_hash(df)
    when = parse_date(test_date)
    if when is None and df.attrs.get("start_time"):
        when = parse_date(str(df.attrs["start_time"]), f"{df.attrs.get('source', 'record')}: "
                          "start time")
    return RecordKey(digest, file_hash(path) if path is not None else digest, when,
                     fingerprint(df))


@dataclass(frozen=True)
class EstimateOptions:
    """How each record is estimated (see :func:`condmon.estimate`).

    ``model`` None: the unit's model (the one its history was started with),
    else ``dc-motor``.
    """

    model: str | None = None
    method: str = "sriv"
    gamma: float | None = None
    excitation: Sequence[str] | str | None = "auto"
    fit_threshold: float = DEFAULT_FIT_THRESHOLD
    columns: dict[str, str] | None = None
    route: str | None = None
    constants: dict[str, float] | None = None

    def run(self, record: RecordLike, test_date: str | datetime | None = None
            ) -> tuple[EstimateResult, RecordKey]:
        """Read (if a path), estimate; returns the result and how the record is known."""
        if isinstance(record, pd.DataFrame):
            key = record_key(record, None, test_date)
            source, mapped = str(record.attrs.get("source", "record")), False
            df = record
        else:
            df = read_record(record, self.columns)
            key, source, mapped = record_key(df, record, test_date), str(record), True
        return self.estimate_parsed(df, source, mapped=mapped), key

    def estimate_parsed(self, df: pd.DataFrame, source: str, *, mapped: bool = True
                        ) -> EstimateResult:
        """Estimate a parsed record (``mapped``: its columns already carry the
        canonical names, else :attr:`columns` maps them); ``source`` names it in
        messages."""
        return estimate(df, self.model or "dc-motor", method=self.method, gamma=self.gamma,
                        excitation=self.excitation, fit_threshold=self.fit_threshold,
                        columns=None if mapped else self.columns, source=source,
                        route=self.route, constants=self.constants)
