"""Tests in the history: adding, excluding, their evaluations, and reading them back."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from datetime import datetime
from typing import Any

import pandas as pd
import sqlalchemy as sa

from condmon.errors import CondmonError, ConfigError
from condmon.store import schema as S
from condmon.store.base import StoreBase, as_utc, check_name, now, num

__all__ = ["TestsMixin", "DuplicateTestError", "TestInfo", "test_values", "stored_estimates",
           "estimate_rows", "evaluation_rows", "insert_evaluation"]


class DuplicateTestError(CondmonError, ValueError):
    """The same record (same content) is already in the unit's history."""

    def __init__(self, message: str, test_id: int) -> None:
        super().__init__(message)
        self.test_id = test_id


def test_values(result: Any, role: str, digest: str, file_digest: str,
                test_date: datetime | None, fingerprint: str | None, hours: float | None
                ) -> dict[str, Any]:
    """A test's ``tests`` row but its ``unit_id`` (see :meth:`TestsMixin.add_test`)."""
    usable = bool(getattr(result, "usable", result.accepted))
    conds = dict(getattr(result, "conditions", {}) or {})
    return dict(
        created_at=now(), source=result.source, file_hash=file_digest, record_hash=digest,
        test_date=test_date, fingerprint=fingerprint, hours=hours,
        regime=getattr(result, "regime_label", "") or None,
        role=role, accepted=usable, reason=None if usable else result.reason,
        fit_percent=num(result.fit_percent),
        fits=json.dumps({k: num(v) for k, v in result.fit.fits_percent.items()}),
        method=result.method, closed_loop=bool(result.closed_loop_instruments),
        constants=json.dumps({k: num(v) for k, v in
                              dict(getattr(result, "constants", {})).items()}),
        conditions=json.dumps({k: [num(v), num(se)] for k, (v, se) in conds.items()})
        if conds else None)


def stored_estimates(result: Any) -> dict[str, tuple[Any, Any]]:
    """The estimate's stored values ``{parameter: (value, standard error)}``.

    Raises
    ------
    ConfigError
        A parameter name the store cannot keep.
    """
    stored = (result.stored_values() if hasattr(result, "stored_values") else
              {p: (v, result.std_errors[p]) for p, v in result.parameters.items()})
    for p in stored:
        check_name(p, "parameter name", limit=S.PARAMETER_LENGTH)
    return dict(stored)


def condition_pairs(doc: str | None) -> dict[str, tuple[float, float]]:
    """A test's stored conditions (``tests.conditions``: JSON ``{name: [value,
    std error]}``) as numbers, NaN for a missing one.

    Example
    -------
    >>> condition_pairs('{"oil@forward": [12200.5, 0.3], "load": [2.0, null]}')
    {'oil@forward': (12200.5, 0.3), 'load': (2.0, nan)}
    """
    out = {}
    for k, v in (json.loads(doc) if doc else {}).items():
        value, se = (v + [None])[:2] if isinstance(v, list) else (v, None)
        out[str(k)] = (float("nan") if value is None else float(value),
                       float("nan") if se is None else float(se))
    return out


def estimate_rows(tid: Any, stored: Mapping[str, tuple[Any, Any]],
                  systematic: Mapping[str, float] | None = None) -> list[dict[str, Any]]:
    """``estimates`` rows of test ``tid``; ``systematic``: each value's
    systematic part (:attr:`~condmon.identify.EstimateResult.systematic`)."""
    sys_ = systematic or {}
    return [{"test_id": tid, "parameter": p, "value": num(v), "std_error": num(se),
             "systematic": num(sys_[p]) if p in sys_ else None}
            for p, (v, se) in stored.items()]


def evaluation_rows(tid: Any, baseline_id: Any, symptoms: Mapping[str, Mapping[str, float]],
                    diagnosis: Any) -> tuple[list[dict[str, Any]], ...]:
    """``symptoms``, ``diagnoses`` and ``diagnosis_faults`` rows of a check's
    evaluation against a baseline version.

    Raises
    ------
    ConfigError
        A fault name the store cannot keep.
    """
    sym = [{"test_id": tid, "parameter": p, "baseline_id": baseline_id,
            "percent_change": float(v["percent_change"]), "high": float(v["high"]),
            "low": float(v["low"])} for p, v in symptoms.items()]
    if diagnosis is None:
        return sym, [], []
    for f in diagnosis.faults:
        check_name(f.name, "fault name")
    return sym, [{"test_id": tid, "baseline_id": baseline_id, "status": diagnosis.status,
                  "condition": float(diagnosis.condition), "summary": diagnosis.summary}], [
        {"test_id": tid, "baseline_id": baseline_id, "name": f.name, "degree": float(f.degree),
         "severity": f.severity, "advice": f.advice} for f in diagnosis.faults]


def insert_evaluation(conn: sa.Connection, tid: int, baseline_id: int,
                      symptoms: Mapping[str, Mapping[str, float]], diagnosis: Any) -> None:
    """Write a check's evaluation (:func:`evaluation_rows`) inside ``conn``'s transaction."""
    for table, rows in zip((S.symptoms, S.diagnoses, S.diagnosis_faults),
                           evaluation_rows(tid, baseline_id, symptoms, diagnosis)):
        if rows:
            conn.execute(sa.insert(table), rows)


class TestInfo(dict):  # type: ignore[type-arg]
    """One test's row (``id, unit, role, accepted, excluded, source, ...``)."""

    __test__ = False  # not a pytest class


ROLES = ("baseline", "check")


class TestsMixin(StoreBase):
    """Tests, their estimates and evaluations (part of :class:`HistoryStore`)."""

    def find_test(self, unit: str, digest: str) -> int | None:
        """Id of the unit's test with this content (or file) hash, if any."""
        def run(c: sa.Connection) -> int | None:
            row = self._unit_row(c, unit)
            if row is None:
                return None
            dup = self._copy_of(c, S.tests, int(row.id), digest, digest)
            return None if dup is None else int(dup[0])

        return self._read(run)

    def copies_elsewhere(self, unit: str, digest: str) -> list[tuple[str, int]]:
        """``(unit, test id)`` of the tests of *other* units with this content
        hash: one test record filed under two machines is most likely a mistake."""
        return self._copies_elsewhere(S.tests, unit, digest)

    def add_test(self, unit: str, result: Any, *, role: str, digest: str,
                 file_digest: str | None = None, test_date: datetime | None = None,
                 hours: float | None = None,
                 fingerprint: str | None = None,
                 symptoms: Mapping[str, Mapping[str, float]] | None = None,
                 baseline_id: int | None = None, diagnosis: Any = None) -> int:
        """Write one test and everything derived from it in one transaction.

        Parameters
        ----------
        unit : str
            Unit name (created on first use).
        result : EstimateResult
            The estimate.
        role : {"baseline", "check"}
        digest : str
            Content hash of the record (:func:`condmon.io.digest.content_hash`):
            the same data in another file is the same test.
        file_digest : str, optional
            SHA-256 of the file's bytes (information; default ``digest``).
        test_date : datetime, optional
            When the test was run (default: unknown; shown by when it was stored).
        hours : float, optional
            The unit's operating hours at the test. [h]
        fingerprint : str, optional
            :func:`condmon.io.digest.fingerprint` of the record: a copy rounded
            otherwise (float32, fewer digits) or with a column more or fewer is
            the same test.
        symptoms : mapping, optional
            ``{param: {"percent_change", "high", "low"}}`` against ``baseline_id``.
        baseline_id : int, optional
        diagnosis : Diagnosis, optional

        Returns
        -------
        int
            The new test's id.

        Raises
        ------
        DuplicateTestError
            The record is already in the unit's history (nothing is written).
        """
        if role not in ROLES:
            raise ConfigError(f"role must be 'baseline' or 'check', got {role!r}")
        check_name(unit)
        fdig = file_digest or digest
        when = as_utc(test_date)

        def run(conn: sa.Connection) -> int:
            uid = self.unit_id(unit, create=True, model=result.model, conn=conn,
                               model_source=getattr(result, "model_source", None))
            dup = self._copy_of(conn, S.tests, uid, digest, fdig, fingerprint)
            if dup is not None:
                note = " (excluded; `condmon include` restores it)" if dup[1] else ""
                raise DuplicateTestError(f"{result.source}: already in the history of {unit!r} "
                                         f"(test #{dup[0]}{note}); not added again", int(dup[0]))
            tid = int(conn.execute(sa.insert(S.tests).values(
                unit_id=uid, **test_values(result, role, digest, fdig, when, fingerprint, hours))
                ).inserted_primary_key[0])  # type: ignore[index]
            stored = stored_estimates(result)
            if stored:
                conn.execute(sa.insert(S.estimates), estimate_rows(
                    tid, stored, getattr(result, "systematic", None)))
            if baseline_id is not None and (symptoms is not None or diagnosis is not None):
                self._insert_evaluation(conn, tid, baseline_id, symptoms or {}, diagnosis)
            usable = bool(getattr(result, "usable", result.accepted))
            self._log(conn, "test added", unit_id=uid, test_id=tid,
                      reason=None if usable else result.reason,
                      detail={"source": result.source, "role": role, "accepted": usable})
            return tid

        return self._write(run, lock=unit)

    def _insert_evaluation(self, conn: sa.Connection, tid: int, baseline_id: int,
                           symptoms: Mapping[str, Mapping[str, float]], diagnosis: Any) -> None:
        insert_evaluation(conn, tid, baseline_id, symptoms, diagnosis)

    def save_evaluation(self, unit: str, test_id: int, baseline_id: int,
                        symptoms: Mapping[str, Mapping[str, float]], diagnosis: Any) -> bool:
        """Store a check's symptoms and diagnosis against another baseline
        version (a re-evaluation after the baseline changed). The evaluations
        against earlier baselines are kept. Returns False when one against
        ``baseline_id`` already exists (nothing written)."""
        def run(conn: sa.Connection) -> bool:
            have = conn.execute(sa.select(S.diagnoses.c.test_id).where(
                S.diagnoses.c.test_id == test_id,
                S.diagnoses.c.baseline_id == baseline_id)).first()
            if have is not None:
                return False
            self._insert_evaluation(conn, test_id, baseline_id, symptoms, diagnosis)
            self._log(conn, "test re-evaluated", unit_id=self.unit_id(unit, conn=conn),
                      test_id=test_id, baseline_id=baseline_id,
                      detail=None if diagnosis is None else {"status": diagnosis.status})
            return True

        return self._write(run, lock=unit)

    def test_info(self, test_id: int) -> TestInfo:
        """One test's row with its unit's name.

        Raises
        ------
        ConfigError
            No such test.
        """
        def run(c: sa.Connection) -> Any:
            t = S.tests
            return c.execute(sa.select(t, S.units.c.name.label("unit"))
                             .join(S.units, S.units.c.id == t.c.unit_id)
                             .where(t.c.id == int(test_id))).mappings().first()

        row = self._read(run)
        if row is None:
            raise ConfigError(f"no test #{test_id} in {self.url} (`condmon history --unit U` "
                              "lists a unit's tests)")
        return TestInfo(row)

    def set_excluded(self, test_id: int, excluded: bool, reason: str | None) -> TestInfo:
        """Exclude a test from baselines and trends (or include it again).

        Nothing is deleted: the test stays, marked, and the change is audited.
        Returns the test's row as it was before.
        """
        info = self.test_info(test_id)

        def run(conn: sa.Connection) -> None:
            conn.execute(sa.update(S.tests).where(S.tests.c.id == int(test_id)).values(
                excluded=bool(excluded), excluded_reason=reason if excluded else None))
            self._log(conn, "test excluded" if excluded else "test included",
                      unit_id=int(info["unit_id"]), test_id=int(test_id), reason=reason,
                      detail={"source": info["source"]})

        self._write(run, lock=str(info["unit"]))
        return info

    def estimates_of(self, test_ids: Sequence[int]) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Values and standard errors (rows: tests in the given order, columns: parameters)."""
        ids = [int(i) for i in test_ids]
        if not ids:
            return pd.DataFrame(), pd.DataFrame()
        rows = self._read(lambda c: c.execute(
            sa.select(S.estimates.c.test_id, S.estimates.c.parameter, S.estimates.c.value,
                      S.estimates.c.std_error).where(S.estimates.c.test_id.in_(ids))).all())
        df = pd.DataFrame(rows, columns=["test_id", "parameter", "value", "se"])
        val = df.pivot(index="test_id", columns="parameter", values="value").reindex(ids)
        se = df.pivot(index="test_id", columns="parameter", values="se").reindex(ids)
        return val, se

    def systematic_of(self, test_ids: Sequence[int]) -> pd.DataFrame:
        """The systematic part of each value (rows: tests in the given order,
        columns: parameters; NaN where none was stated). [parameter units]"""
        ids = [int(i) for i in test_ids]
        if not ids:
            return pd.DataFrame()
        rows = self._read(lambda c: c.execute(
            sa.select(S.estimates.c.test_id, S.estimates.c.parameter,
                      S.estimates.c.systematic).where(S.estimates.c.test_id.in_(ids))).all())
        df = pd.DataFrame(rows, columns=["test_id", "parameter", "systematic"])
        df["systematic"] = pd.to_numeric(df["systematic"], errors="coerce")
        return df.pivot(index="test_id", columns="parameter", values="systematic").reindex(ids)

    def conditions_of(self, test_ids: Sequence[int]) -> tuple[pd.DataFrame, pd.DataFrame]:
        """The operating conditions of tests and their standard errors (rows:
        tests in the given order, columns: conditions, ``oil@forward``; NaN
        where a test has none). [condition units]"""
        ids = [int(i) for i in test_ids]
        if not ids:
            return pd.DataFrame(), pd.DataFrame()
        rows = self._read(lambda c: c.execute(
            sa.select(S.tests.c.id, S.tests.c.conditions)
            .where(S.tests.c.id.in_(ids))).all())
        docs = {int(i): condition_pairs(doc) for i, doc in rows}
        index = pd.Index(ids, name="test_id")
        values = pd.DataFrame([{k: v[0] for k, v in docs.get(i, {}).items()} for i in ids],
                              index=index, dtype="float64")
        errors = pd.DataFrame([{k: v[1] for k, v in docs.get(i, {}).items()} for i in ids],
                              index=index, dtype="float64")
        return values, errors

    def usable_tests(self, unit: str, role: str | None = None) -> list[int]:
        """Ids of the unit's accepted, not excluded tests of ``role`` (None:
        every role), oldest first; empty for an unknown unit."""
        def run(c: sa.Connection) -> list[int]:
            t = S.tests
            q = (sa.select(t.c.id).join(S.units, S.units.c.id == t.c.unit_id)
                 .where(S.units.c.name == unit, t.c.accepted.is_(True),
                        t.c.excluded.is_(False)))
            if role is not None:
                q = q.where(t.c.role == role)
            return [int(r[0]) for r in c.execute(q.order_by(t.c.id))]

        return self._read(run)

    def start_times(self, unit: str) -> list[float]:
        """The start times of every record of the unit the history holds with a
        date (any role, excluded or not: each says the unit was running), as
        POSIX seconds; empty for an unknown unit. [s]"""
        def run(c: sa.Connection) -> list[Any]:
            t = S.tests
            q = (sa.select(t.c.test_date).join(S.units, S.units.c.id == t.c.unit_id)
                 .where(S.units.c.name == unit, t.c.test_date.is_not(None)))
            return [r[0] for r in c.execute(q)]

        return [when.timestamp() for when in map(as_utc, self._read(run)) if when is not None]

    def accepted_estimates(self, unit: str, role: str | None = "baseline"
                           ) -> tuple[list[int], pd.DataFrame]:
        """Ids and parameter table (rows: tests, columns: parameters) of the
        unit's accepted, not excluded tests of ``role`` (None: every role),
        oldest first."""
        def run(c: sa.Connection) -> list[Any]:
            q = (sa.select(S.tests.c.id, S.estimates.c.parameter, S.estimates.c.value)
                 .join(S.units, S.units.c.id == S.tests.c.unit_id)
                 .join(S.estimates, S.estimates.c.test_id == S.tests.c.id)
                 .where(S.units.c.name == unit, S.tests.c.accepted.is_(True),
                        S.tests.c.excluded.is_(False)))
            if role is not None:
                q = q.where(S.tests.c.role == role)
            return list(c.execute(q.order_by(S.tests.c.id)).all())

        rows = self._read(run)
        if not rows:
            return [], pd.DataFrame()
        df = pd.DataFrame(rows, columns=["test_id", "parameter", "value"])
        wide = df.pivot(index="test_id", columns="parameter", values="value")
        return [int(i) for i in wide.index], wide[self._ordered(unit, list(wide.columns))]

