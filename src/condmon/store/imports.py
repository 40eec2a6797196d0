"""Imported indicator values in the history: one transaction per unit, and
each unit's own end of life (part of :class:`~condmon.store.HistoryStore`).

An imported value is a test like an estimated one (``tests``, its values in
``estimates``, its evaluation in ``symptoms`` and ``diagnoses``), with
``method = "import"``, no fit, and the unit's cycle, operating hours or date
as its place on the unit's axis. A row already in the history (the same
unit, place and values: its ``record_hash``) is not stored twice.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import sqlalchemy as sa

from condmon.errors import ConfigError
from condmon.store import schema as S
from condmon.store.base import StoreBase, as_utc, check_name, now, num
from condmon.store.baselines import DEFAULT_BASELINE, baseline_value_rows
from condmon.store.history import estimate_rows, insert_evaluation

__all__ = ["ImportedTest", "ImportsMixin"]


@dataclass(frozen=True)
class ImportedTest:
    """One imported row, ready to store.

    Attributes
    ----------
    source : str
        ``file:row N``.
    record_hash : str
        What makes it the same row again.
    values : dict of str to (float, float or None)
        ``{indicator: (value, standard error)}``. [indicator units]
    role : {"baseline", "check"}
    cycle, hours : float or None
        Its place on the unit's axis. [cycle, h]
    test_date : datetime or None
    evaluation : object, optional
        The check's judgement (:class:`~condmon.monitor.indicators.IndicatorJudgement`).
    """

    source: str
    record_hash: str
    values: dict[str, tuple[float, float | None]]
    role: str
    cycle: float | None = None
    hours: float | None = None
    test_date: datetime | None = None
    evaluation: Any = field(default=None, compare=False)


class ImportsMixin(StoreBase):
    """Imported values and each unit's end of life (part of :class:`HistoryStore`)."""

    def imported_hashes(self, unit: str) -> set[str]:
        """The record hashes of ``unit``'s tests (none: an unknown unit)."""
        def run(c: sa.Connection) -> set[str]:
            row = self._unit_row(c, unit)
            if row is None:
                return set()
            return {str(r[0]) for r in c.execute(
                sa.select(S.tests.c.record_hash).where(S.tests.c.unit_id == row.id))}

        return self._read(run)

    def add_imported(self, unit: str, model: str, model_source: str | None,
                     tests: Sequence[ImportedTest], *, baseline: Any = None,
                     baseline_id: int | None = None,
                     end_of_life: Mapping[str, str] | None = None) -> list[int]:
        """Store a unit's imported rows, in one transaction.

        Parameters
        ----------
        unit, model, model_source : str
            The unit (created on first use) and its declaration.
        tests : sequence of ImportedTest
        baseline : Baseline, optional
            A new baseline made of the tests whose role is "baseline".
        baseline_id : int, optional
            The stored baseline the checks were judged against (without ``baseline``).
        end_of_life : mapping, optional
            The unit's own end of life per indicator, as written (``"< 0.88"``).

        Returns
        -------
        list of int
            The new tests' ids.

        Raises
        ------
        ConfigError
            The unit is of another model, or a name the store cannot keep.
        """
        check_name(unit)

        def run(conn: sa.Connection) -> list[int]:
            row = self._unit_row(conn, unit)
            if row is not None and row.model != model:
                raise ConfigError(f"unit {unit!r} is of model {row.model!r}, not {model!r}; "
                                  "import its values with its own declaration")
            uid = self.unit_id(unit, create=True, model=model, conn=conn,
                               model_source=model_source)
            before = {} if row is None or not row.end_of_life else json.loads(row.end_of_life)
            if end_of_life and dict(end_of_life) != before:
                conn.execute(sa.update(S.units).where(S.units.c.id == uid).values(
                    end_of_life=json.dumps(dict(end_of_life))))
                # (an audit row: the unit's kept forecast and listing are of the old one)
                self._log(conn, "end of life changed", unit_id=uid,
                          detail={"from": before, "to": dict(end_of_life)})
            ids = []
            for t in tests:
                tid = int(conn.execute(sa.insert(S.tests).values(
                    unit_id=uid, created_at=now(), source=t.source, file_hash=t.record_hash,
                    record_hash=t.record_hash, test_date=as_utc(t.test_date),
                    hours=num(t.hours), cycle=num(t.cycle), role=t.role, accepted=True,
                    reason=None, fit_percent=None, fits="{}", method="import",
                    closed_loop=False, constants="{}", conditions=None)
                ).inserted_primary_key[0])  # type: ignore[index]
                conn.execute(sa.insert(S.estimates), estimate_rows(tid, t.values, None))
                ids.append(tid)
            bid = baseline_id
            if baseline is not None:
                members = [i for i, t in zip(ids, tests) if t.role == "baseline"]
                label = str(row.baseline_name if row is not None else DEFAULT_BASELINE)
                last = conn.execute(sa.select(sa.func.max(S.baselines.c.version)).where(
                    S.baselines.c.unit_id == uid, S.baselines.c.name == label)).scalar()
                bid = int(conn.execute(sa.insert(S.baselines).values(
                    unit_id=uid, created_at=now(), n=int(baseline.n),
                    test_ids=json.dumps(members), name=label, version=int(last or 0) + 1,
                    reason="imported", flags="[]")).inserted_primary_key[0])  # type: ignore[index]
                conn.execute(sa.insert(S.baseline_values), baseline_value_rows(bid, baseline))
                self._log(conn, "baseline saved", unit_id=uid, baseline_id=bid,
                          reason="imported", detail={"name": label, "test_ids": members})
            for tid, t in zip(ids, tests):
                if t.evaluation is not None and bid is not None:
                    insert_evaluation(conn, tid, bid, t.evaluation.symptoms, t.evaluation)
            if ids:
                self._log(conn, "tests imported", unit_id=uid, test_id=ids[-1],
                          detail={"tests": len(ids), "first": tests[0].source,
                                  "last": tests[-1].source})
            return ids

        return self._write(run, lock=unit)

    def indicator_model(self, unit: str) -> Any:
        """The unit's :class:`~condmon.models.indicators.IndicatorModel`, with
        its own end of life (None: the unit's model is not an indicator
        declaration, or the unit is unknown).

        Raises
        ------
        ConfigError
            Its declaration or its own end of life cannot be read.
        """
        from condmon.models.indicators import with_own_end_of_life
        from condmon.models.registry import get_model

        try:
            source = self.unit_model(unit)
        except ConfigError:
            return None
        if not source:
            return None
        model = get_model(source).indicators   # (the registry's cache: read once)
        if model is None:
            return None
        return with_own_end_of_life(model, self.end_of_life(unit), f"unit {unit!r}")

    def end_of_life(self, unit: str) -> dict[str, str]:
        """The unit's own end of life per indicator, as written (none: {})."""
        def run(c: sa.Connection) -> dict[str, str]:
            row = self._unit_row(c, unit)
            if row is None or not row.end_of_life:
                return {}
            try:
                doc = json.loads(row.end_of_life)
            except ValueError:
                return {}
            return {str(k): str(v) for k, v in doc.items()} if isinstance(doc, dict) else {}

        return self._read(run)
