"""One record as the workflows know it: read, estimated, and keyed for the
history (content hash, file hash, test date). Nothing here touches the store, so
``condmon estimate`` and a fleet worker pay for no database import."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union


from condmon.errors import DataError
from condmon.identify.estimate import EstimateResult, estimate
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD
from condmon.io.columns import Columns, read_plain_csv
from condmon.io.dates import parse_date
from condmon.io.digest import content_hash, file_hash, fingerprint
from condmon.io.records import read_record
from condmon.io.rig import RecordSettings, apply_record_settings

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["EstimateOptions", "RecordKey", "RecordLike", "Cycle", "record_key"]

#: A record file, or a record already read.
RecordLike = Union[str, Path, "pd.DataFrame", Columns]


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
    hours : float or None
        The unit's operating hours at the test: the record's ``hours``
        metadata field (``--meta hours=1234``, a unit folder's or a manifest
        row's metadata), if any. [h]
    """

    content: str
    file: str
    test_date: datetime | None
    fingerprint: str | None = None
    hours: float | None = None


def record_key(df: pd.DataFrame | Columns, path: str | Path | None = None,
               test_date: str | datetime | None = None,
               metadata: Mapping[str, Any] | None = None) -> RecordKey:
    """The :class:`RecordKey` of a parsed record (``path``: its file, if any;
    ``metadata``: its fields, of which ``hours`` is the unit's usage).

    Raises
    ------
    DataError
        ``hours`` that is not a finite number >= 0.
    """
    digest = content_hash(df)
    hours = usage_hours((metadata or {}).get("hours"), str(path or df.attrs.get("source",
                                                                                "record")))
    when = parse_date(test_date)
    if when is None and df.attrs.get("start_time"):
        when = parse_date(str(df.attrs["start_time"]), f"{df.attrs.get('source', 'record')}: "
                          "start time")
    return RecordKey(digest, file_hash(path) if path is not None else digest, when,
                     fingerprint(df), hours)


def usage_hours(value: Any, source: str) -> float | None:
    """A record's ``hours`` metadata as operating hours, None when not given. [h]

    Example
    -------
    >>> usage_hours("1250.5", "rec.csv"), usage_hours(None, "rec.csv")
    (1250.5, None)
    """
    if value is None or value == "":
        return None
    try:
        hours = float(value)
    except (TypeError, ValueError):
        raise DataError(f"{source}: metadata 'hours' must be the unit's operating hours, a "
                        f"number >= 0, not {value!r}") from None
    if not (math.isfinite(hours) and hours >= 0):
        raise DataError(f"{source}: metadata 'hours' must be a finite number >= 0 [h], "
                        f"not {hours:g}")
    return hours


@dataclass(frozen=True)
class Cycle:
    """The records of one test, estimated together
    (:func:`~condmon.identify.estimate.estimate_joint`): a machine's cycle
    written as several files (a stroke each way), ``[estimation] cycle``.

    Example
    -------
    >>> Cycle(("Base_000_4.txt", "Base_000_5.txt")).source
    'Base_000_4.txt + Base_000_5.txt'
    """

    records: tuple[RecordLike, ...]
    #: The records already read (with their record settings), when the grouping
    #: read them: not read twice. Not part of the test's identity.
    frames: tuple[pd.DataFrame | Columns, ...] = dataclasses.field(
        default=(), compare=False, repr=False)

    @property
    def source(self) -> str:
        """The records' names joined with " + " (as the estimate names them)."""
        return " + ".join(str(r) if isinstance(r, (str, Path))
                          else str(r.attrs.get("source", f"record {i + 1}"))
                          for i, r in enumerate(self.records))


def cycle_key(keys: Sequence[RecordKey]) -> RecordKey:
    """How a test of several records is known: its records' hashes, sorted (the
    same records in another order are the same test) and hashed again; the
    earliest record's date and its hours (no fingerprint: a rounded copy is
    told by each record's own, not by the test's)."""
    import hashlib

    def joined(parts: Sequence[str]) -> str:
        return hashlib.sha256("+".join(sorted(parts)).encode()).hexdigest()

    dated = sorted((k.test_date, i) for i, k in enumerate(keys) if k.test_date is not None)
    first = keys[dated[0][1]] if dated else keys[0]
    return RecordKey(joined([k.content for k in keys]), joined([k.file for k in keys]),
                     first.test_date, None, first.hours)


@dataclass(frozen=True)
class EstimateOptions:
    """How each record is read and estimated (see :func:`condmon.estimate`).

    ``model`` None: the unit's model (the one its history was started with),
    else ``dc-motor``. ``record``: how the rig writes its files, over the
    model's own ``[record]`` table (a unit folder's ``unit.toml``, a manifest
    row and the command line merged, the later winning); ``columns`` maps
    names on top. ``metadata``: the record's fields the regimes may name
    (``load = "ball"``). ``window``: a span chosen by hand [s]. ``hold``:
    values for unknowns a record does not identify (a unit's baseline).
    """

    model: str | None = None
    method: str = "sriv"
    gamma: float | None = None
    excitation: Sequence[str] | str | None = "auto"
    fit_threshold: float = DEFAULT_FIT_THRESHOLD
    columns: dict[str, str] | None = None
    route: str | None = None
    constants: dict[str, float] | None = None
    record: RecordSettings | None = None
    metadata: dict[str, Any] | None = None
    window: tuple[float, float] | None = None
    hold: dict[str, float] | None = None

    def settings(self) -> RecordSettings:
        """The record settings in force: the model's ``[record]``, then
        :attr:`record`, then :attr:`columns`."""
        from condmon.models.registry import get_model

        machine = get_model(self.model or "dc-motor")
        if self.columns:
            _check_mapped(machine, self.columns)
        return machine.record.merged(self.record).merged(
            RecordSettings(dict(self.columns or {}), sources=("--columns",) if self.columns
                           else ()))

    def read(self, record: str | Path) -> pd.DataFrame | Columns:
        """Read a record file and apply the record settings (model columns, SI units).

        A plain CSV file with nothing to convert but names is read without
        pandas (:func:`condmon.io.columns.read_plain_csv`), as :class:`Columns`."""
        from condmon.models.registry import recognised_records

        settings = self.settings()
        rest = dataclasses.replace(settings, columns={})
        plain = read_plain_csv(record, settings.columns) if rest.empty else None
        out: pd.DataFrame | Columns
        if plain is not None:
            out = plain
        else:
            with recognised_records(self.model or "dc-motor"):
                df = read_record(record, settings.columns)
            out = apply_record_settings(df, rest, str(record), renamed=settings.columns)
        out.attrs["record_settings"] = settings.describe(len(out.attrs.get("record_ignored", ())))
        return out

    def prepared(self, record: pd.DataFrame | Columns) -> pd.DataFrame | Columns:
        """An in-memory record with the record settings applied (once)."""
        if record.attrs.get("record_settings") is not None:
            return record
        settings = self.settings()
        if settings.empty:
            record.attrs.setdefault("record_settings", "as written")
            return record
        out = apply_record_settings(record.to_frame() if isinstance(record, Columns) else record,
                                    settings)
        out.attrs.setdefault("record_settings", "as written")
        return out

    def run(self, record: RecordLike, test_date: str | datetime | None = None
            ) -> tuple[EstimateResult, RecordKey]:
        """Read (if a path), estimate; returns the result and how the record is known."""
        df, key, source = self.parse(record, test_date)
        return self.estimate_parsed(df, source), key

    def parse(self, record: RecordLike, test_date: str | datetime | None = None,
              read: pd.DataFrame | Columns | None = None
              ) -> tuple[pd.DataFrame | Columns, RecordKey, str]:
        """Read (if a path) and apply the record settings: the record in model
        columns, how it is known, and its name for messages; ``read``: the
        record already read so (not read again)."""
        if not isinstance(record, (str, Path)):
            df = self.prepared(record) if read is None else read
            return (df, record_key(df, None, test_date, self.metadata),
                    str(record.attrs.get("source", "record")))
        df = self.read(record) if read is None else read
        return df, record_key(df, record, test_date, self.metadata), str(record)

    def unit_hint(self, df: pd.DataFrame | Columns, source: str,
                  accept: Callable[[EstimateResult], bool],
                  reference: Mapping[str, float] | None = None) -> str:
        """Which column's unit would explain a refused estimate of ``df``
        (:func:`condmon.identify.unit_errors.unit_suspects`), as a clause
        starting with "; " (empty when none does)."""
        from condmon.identify.unit_errors import suspect_text, unit_suspects
        from condmon.models.registry import get_model

        plant = get_model(self.model or "dc-motor").plant
        columns = {c.name: (c.unit, c.description) for c in plant.sensors}
        columns.update({u.name: (u.unit, u.description) for u in plant.inputs})
        found = unit_suspects(df, columns, lambda cols: self.estimate_parsed(cols, source),
                              accept, reference)
        return f"; {suspect_text(found)}" if found else ""

    def estimate_parsed(self, df: pd.DataFrame | Columns, source: str, *, mapped: bool = True
                        ) -> EstimateResult:
        """Estimate a parsed record (``mapped``: the record settings were
        applied, as :meth:`read` does; else they are applied now); ``source``
        names it in messages."""
        frame = df if mapped else self.prepared(df)
        return estimate(frame, self.model or "dc-motor", method=self.method, gamma=self.gamma,
                        excitation=self.excitation, fit_threshold=self.fit_threshold,
                        source=source, route=self.route, constants=self.constants,
                        metadata=self.metadata, window=self.window, hold=self.hold)

    def run_cycle(self, cycle: Cycle, test_date: str | datetime | None = None
                  ) -> tuple[EstimateResult, RecordKey]:
        """Read (where paths) and estimate a test's records together; the
        result and how the test is known (:func:`cycle_key`)."""
        from condmon.identify.estimate import estimate_joint

        if self.window is not None and len(cycle.records) > 1:
            raise DataError(f"{cycle.source}: --window applies to one record; a test of "
                            "several records is estimated over their windows")
        frames = cycle.frames if len(cycle.frames) == len(cycle.records) else \
            (None,) * len(cycle.records)   # (read by the grouping: not read twice)
        parsed = [self.parse(r, test_date, df) for r, df in zip(cycle.records, frames)]
        res = estimate_joint([df for df, _, _ in parsed], self.model or "dc-motor",
                             fit_threshold=self.fit_threshold,
                             sources=[src for _, _, src in parsed], route=self.route,
                             constants=self.constants, metadata=self.metadata, hold=self.hold,
                             window=self.window)
        return res, cycle_key([key for _, key, _ in parsed])

    def with_hold(self, hold: Mapping[str, float] | None) -> EstimateOptions:
        """These options holding unidentified unknowns at ``hold`` (a baseline's means)."""
        return dataclasses.replace(self, hold=dict(hold) if hold else None)


def _check_mapped(machine: Any, columns: Mapping[str, str]) -> None:
    """Refuse ``--columns`` naming a state or a parameter: a record holds ``t``,
    the sensors and the inputs, which are what a file column maps to."""
    plant = machine.plant
    record = ["t", *plant.sensor_names, *(u.name for u in plant.inputs)]
    for name in columns:
        if name in record:
            continue  # a sensor may share its state's name (dc-motor's I, omega)
        what = ("a state" if name in {x.name for x in plant.states} else
                "a parameter" if name in plant.parameter_names else None)
        if what is None:
            continue
        measured = [sn.name for sn in plant.sensors if sn.measures == name]
        hint = (f"; its sensor is {measured[0]!r}: write {measured[0]}={columns[name]}"
                if measured else "")
        raise DataError(f"--columns {name}={columns[name]}: {name!r} is {what} of model "
                        f"{machine.name!r}, not a record column; a record holds "
                        f"{', '.join(record)}{hint}")
