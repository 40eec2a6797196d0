"""The history store: units, tests, estimates, baselines, symptoms and diagnoses.

SQLite by default (one file), PostgreSQL for shared use, through one SQLAlchemy
code path. Each test is written in a single transaction (test row, its
estimates, symptoms and diagnosis together), so an interruption leaves either
the whole test or nothing. The same file added twice to a unit is detected by
its SHA-256 and not duplicated.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import sqlalchemy as sa

from condmon.errors import CondmonError, ConfigError
from condmon.store import schema as S

__all__ = ["HistoryStore", "open_store", "file_hash", "frame_hash", "DuplicateTestError",
           "StoreError", "StoredTest"]


class StoreError(CondmonError, RuntimeError):
    """The database cannot be used (unreachable, newer schema, ...)."""


class DuplicateTestError(CondmonError, ValueError):
    """The same record is already in the unit's history."""

    def __init__(self, message: str, test_id: int) -> None:
        super().__init__(message)
        self.test_id = test_id


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def frame_hash(df: pd.DataFrame) -> str:
    """SHA-256 of a DataFrame's contents (for records that never were files)."""
    h = hashlib.sha256()
    h.update(",".join(map(str, df.columns)).encode())
    h.update(pd.util.hash_pandas_object(df, index=False).to_numpy().tobytes())
    return h.hexdigest()


def _url(db: str | Path) -> str:
    text = str(db)
    if "://" not in text:
        return f"sqlite:///{Path(text).expanduser()}"
    if text.startswith("postgresql://") or text.startswith("postgres://"):
        return "postgresql+psycopg://" + text.split("://", 1)[1]
    return text


def _now() -> datetime:
    return datetime.now(timezone.utc)


def _num(x: float) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


@dataclass(frozen=True)
class StoredTest:
    """What the store wrote for one test (id and whether it was new)."""

    test_id: int
    created: bool


class HistoryStore:
    """A history database. Open with :func:`open_store`.

    Use it as a context manager (or call :meth:`close`) so that its connections
    are released.

    Example
    -------
    >>> with open_store("sqlite://") as store:        # in memory
    ...     store.unit_id("EMA-1", create=True)
    1
    """

    def __init__(self, engine: sa.Engine, url: str) -> None:
        self.engine = engine
        self.url = url

    def close(self) -> None:
        """Release every pooled connection."""
        self.engine.dispose()

    def __enter__(self) -> HistoryStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- schema -------------------------------------------------------------------------
    def _init_schema(self) -> None:
        with self.engine.begin() as conn:
            S.metadata.create_all(conn)
            row = conn.execute(sa.select(S.meta.c.value).where(S.meta.c.key == "schema_version")).first()
            if row is None:
                conn.execute(sa.insert(S.meta).values(key="schema_version",
                                                      value=str(S.SCHEMA_VERSION)))
                return
            version = int(row[0])
            if version > S.SCHEMA_VERSION:
                raise StoreError(f"{self.url}: database schema v{version} is newer than this "
                                 f"condmon (v{S.SCHEMA_VERSION}); upgrade condmon")
            while version < S.SCHEMA_VERSION:
                if version not in S.MIGRATIONS:
                    raise StoreError(f"{self.url}: no migration from schema v{version}")
                S.MIGRATIONS[version](conn)
                version += 1
                conn.execute(sa.update(S.meta).where(S.meta.c.key == "schema_version")
                             .values(value=str(version)))

    @property
    def schema_version(self) -> int:
        """Schema version recorded in the database."""
        with self.engine.connect() as conn:
            v = conn.execute(sa.select(S.meta.c.value).where(S.meta.c.key == "schema_version")).scalar_one()
        return int(v)

    # -- units --------------------------------------------------------------------------
    def unit_id(self, name: str, *, create: bool = False, model: str = "dc-motor",
                conn: sa.Connection | None = None, model_source: str | None = None) -> int:
        """Id of unit ``name``; created when ``create`` (else an error naming the units)."""
        def run(c: sa.Connection) -> int:
            uid = c.execute(sa.select(S.units.c.id).where(S.units.c.name == name)).scalar()
            if uid is not None:
                return int(uid)
            if not create:
                known = [r[0] for r in c.execute(sa.select(S.units.c.name).order_by(S.units.c.name))]
                raise ConfigError(f"unknown unit {name!r} in {self.url}; units: {known or 'none yet'}")
            res = c.execute(sa.insert(S.units).values(name=name, model=model, created_at=_now(),
                                                      model_source=model_source))
            return int(res.inserted_primary_key[0])  # type: ignore[index]

        if conn is not None:
            return run(conn)
        with self.engine.begin() as c:
            return run(c)

    def unit_model(self, unit: str) -> str | None:
        """The unit's model: its declaration file when it is not a shipped model,
        else its name (None for an unknown unit)."""
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(S.units.c.model, S.units.c.model_source)
                               .where(S.units.c.name == unit)).first()
        if row is None:
            return None
        return str(row[1]) if row[1] else str(row[0])

    def unit_summaries(self) -> list[dict[str, Any]]:
        """Every unit with its model, number of tests, latest test and its status
        ("baseline", "retest" for a rejected check, else the check's status)."""
        with self.engine.connect() as conn:
            units = conn.execute(sa.select(S.units.c.id, S.units.c.name, S.units.c.model,
                                           S.units.c.model_source)
                                 .order_by(S.units.c.name)).all()
            out = []
            for uid, name, model, source in units:
                t = S.tests
                n = conn.execute(sa.select(sa.func.count()).select_from(t)
                                 .where(t.c.unit_id == uid)).scalar_one()
                last = conn.execute(
                    sa.select(t.c.source, t.c.role, t.c.accepted, S.diagnoses.c.status)
                    .outerjoin(S.diagnoses, S.diagnoses.c.test_id == t.c.id)
                    .where(t.c.unit_id == uid).order_by(t.c.id.desc()).limit(1)).first()
                status = None
                if last is not None:
                    status = ("baseline" if last[1] == "baseline"
                              else (last[3] if last[2] else "retest"))
                out.append({"unit": name, "model": source or model, "tests": int(n),
                            "latest_source": None if last is None else last[0],
                            "status": status})
        return out

    def units(self) -> list[str]:
        """Names of every unit."""
        with self.engine.connect() as conn:
            return [r[0] for r in conn.execute(sa.select(S.units.c.name).order_by(S.units.c.name))]

    # -- tests --------------------------------------------------------------------------
    def find_test(self, unit: str, digest: str) -> int | None:
        """Id of the unit's test with this file hash, if any."""
        with self.engine.connect() as conn:
            q = (sa.select(S.tests.c.id).join(S.units, S.units.c.id == S.tests.c.unit_id)
                 .where(S.units.c.name == unit, S.tests.c.file_hash == digest))
            tid = conn.execute(q).scalar()
        return None if tid is None else int(tid)

    def add_test(self, unit: str, result: Any, *, role: str, digest: str,
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
            SHA-256 of the record (duplicate detection).
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
        if role not in ("baseline", "check"):
            raise ValueError(f"role must be 'baseline' or 'check', got {role!r}")
        existing = self.find_test(unit, digest)
        if existing is not None:
            raise DuplicateTestError(f"{result.source}: already in the history of {unit!r} "
                                     f"(test #{existing}); not added again", existing)
        with self.engine.begin() as conn:
            uid = self.unit_id(unit, create=True, model=result.model, conn=conn,
                               model_source=getattr(result, "model_source", None))
            res = conn.execute(sa.insert(S.tests).values(
                unit_id=uid, created_at=_now(), source=result.source, file_hash=digest,
                role=role, accepted=bool(result.accepted), reason=result.reason,
                fit_percent=_num(result.fit_percent),
                fits=json.dumps({k: _num(v) for k, v in result.fit.fits_percent.items()}),
                method=result.method, closed_loop=bool(result.closed_loop_instruments),
                constants=json.dumps({k: _num(v) for k, v in
                                      dict(getattr(result, "constants", {})).items()})))
            tid = int(res.inserted_primary_key[0])  # type: ignore[index]
            conn.execute(sa.insert(S.estimates), [
                {"test_id": tid, "parameter": p, "value": _num(v),
                 "std_error": _num(result.std_errors[p])}
                for p, v in result.parameters.items()])
            if symptoms is not None and baseline_id is not None:
                conn.execute(sa.insert(S.symptoms), [
                    {"test_id": tid, "parameter": p, "baseline_id": baseline_id,
                     "percent_change": float(v["percent_change"]), "high": float(v["high"]),
                     "low": float(v["low"])} for p, v in symptoms.items()])
            if diagnosis is not None and baseline_id is not None:
                conn.execute(sa.insert(S.diagnoses).values(
                    test_id=tid, baseline_id=baseline_id, status=diagnosis.status,
                    condition=float(diagnosis.condition), summary=diagnosis.summary))
                if diagnosis.faults:
                    conn.execute(sa.insert(S.diagnosis_faults), [
                        {"test_id": tid, "name": f.name, "degree": float(f.degree),
                         "severity": f.severity, "advice": f.advice} for f in diagnosis.faults])
        return tid

    def accepted_estimates(self, unit: str, role: str | None = "baseline"
                           ) -> tuple[list[int], pd.DataFrame]:
        """Ids and parameter table (rows: tests, columns: parameters) of the
        unit's accepted tests of ``role`` (None: every role), oldest first."""
        with self.engine.connect() as conn:
            q = (sa.select(S.tests.c.id, S.estimates.c.parameter, S.estimates.c.value)
                 .join(S.units, S.units.c.id == S.tests.c.unit_id)
                 .join(S.estimates, S.estimates.c.test_id == S.tests.c.id)
                 .where(S.units.c.name == unit, S.tests.c.accepted.is_(True)))
            if role is not None:
                q = q.where(S.tests.c.role == role)
            rows = conn.execute(q.order_by(S.tests.c.id)).all()
        if not rows:
            return [], pd.DataFrame()
        df = pd.DataFrame(rows, columns=["test_id", "parameter", "value"])
        wide = df.pivot(index="test_id", columns="parameter", values="value")
        return [int(i) for i in wide.index], wide[self._ordered(unit, list(wide.columns))]

    def _ordered(self, unit: str, names: list[str]) -> list[str]:
        """Parameter names in the unit's model order (unknown ones last, sorted)."""
        from condmon.errors import ModelError
        from condmon.models.registry import get_model

        model = self.unit_model(unit)
        try:
            order = list(get_model(model).spec.report) if model else []
        except (ModelError, ConfigError):
            order = []
        return [p for p in order if p in names] + sorted(p for p in names if p not in order)

    # -- baselines ----------------------------------------------------------------------
    def save_baseline(self, unit: str, baseline: Any, test_ids: Sequence[int]) -> int:
        """Store a baseline snapshot; returns its id (reuses an identical latest one)."""
        ids = json.dumps(sorted(int(i) for i in test_ids))
        with self.engine.begin() as conn:
            uid = self.unit_id(unit, create=True, conn=conn)
            last = conn.execute(sa.select(S.baselines.c.id, S.baselines.c.test_ids)
                                .where(S.baselines.c.unit_id == uid)
                                .order_by(S.baselines.c.id.desc()).limit(1)).first()
            if last is not None and last[1] == ids:
                return int(last[0])
            res = conn.execute(sa.insert(S.baselines).values(
                unit_id=uid, created_at=_now(), n=int(baseline.n), test_ids=ids))
            bid = int(res.inserted_primary_key[0])  # type: ignore[index]
            conn.execute(sa.insert(S.baseline_values), [
                {"baseline_id": bid, "parameter": p, "mean": m, "std": s}
                for p, m, s in zip(baseline.parameters, baseline.mean, baseline.std)])
        return bid

    # -- reading back -------------------------------------------------------------------
    def history(self, unit: str) -> pd.DataFrame:
        """One row per test of the unit, oldest first.

        Columns: ``test_id, created_at, source, role, accepted, reason, fit_percent,
        method, status, summary``, then each parameter's value and, for checked
        tests, ``<param>_change`` [%], ``<param>_high``, ``<param>_low``.
        """
        self.unit_id(unit)  # clear error for an unknown unit
        with self.engine.connect() as conn:
            t = S.tests
            base = conn.execute(
                sa.select(t.c.id, t.c.created_at, t.c.source, t.c.role, t.c.accepted,
                          t.c.reason, t.c.fit_percent, t.c.fits, t.c.method,
                          S.diagnoses.c.status, S.diagnoses.c.summary)
                .join(S.units, S.units.c.id == t.c.unit_id)
                .outerjoin(S.diagnoses, S.diagnoses.c.test_id == t.c.id)
                .where(S.units.c.name == unit).order_by(t.c.id)).all()
            est = conn.execute(
                sa.select(S.estimates.c.test_id, S.estimates.c.parameter, S.estimates.c.value)
                .join(t, t.c.id == S.estimates.c.test_id)
                .join(S.units, S.units.c.id == t.c.unit_id).where(S.units.c.name == unit)).all()
            sym = conn.execute(
                sa.select(S.symptoms.c.test_id, S.symptoms.c.parameter,
                          S.symptoms.c.percent_change, S.symptoms.c.high, S.symptoms.c.low)
                .join(t, t.c.id == S.symptoms.c.test_id)
                .join(S.units, S.units.c.id == t.c.unit_id).where(S.units.c.name == unit)).all()
        cols = ["test_id", "created_at", "source", "role", "accepted", "reason",
                "fit_percent", "fits", "method", "status", "summary"]
        df = pd.DataFrame(base, columns=cols).set_index("test_id")
        if est:
            e = pd.DataFrame(est, columns=["test_id", "parameter", "value"]).pivot(
                index="test_id", columns="parameter", values="value")
            df = df.join(e[self._ordered(unit, list(e.columns))])
        if sym:
            s = pd.DataFrame(sym, columns=["test_id", "parameter", "change", "high", "low"])
            for col in ("change", "high", "low"):
                w = s.pivot(index="test_id", columns="parameter", values=col)
                w.columns = [f"{c}_{col}" for c in w.columns]
                df = df.join(w)
        return df


def open_store(db: str | Path, *, create: bool = True) -> HistoryStore:
    """Open (and create or migrate) a history database.

    Parameters
    ----------
    db : str or Path
        A file path (SQLite), ``sqlite://`` (in memory) or a database URL such as
        ``postgresql://user@host/dbname``.
    create : bool
        Create a missing SQLite file. False for commands that only read (a
        mistyped path is then an error, not a new empty history).

    Returns
    -------
    HistoryStore

    Raises
    ------
    StoreError
        The database cannot be opened (or, with ``create=False``, does not exist).
    """
    url = _url(db)
    if not create and url.startswith("sqlite:///") and not Path(url[len("sqlite:///"):]).exists():
        raise StoreError(f"{db}: no history database there (check the path; `baseline add` "
                         "creates one)")
    try:
        engine = sa.create_engine(url)
        if engine.dialect.name == "sqlite":
            @sa.event.listens_for(engine, "connect")
            def _fk(dbapi_conn: Any, _: Any) -> None:  # enforce foreign keys in SQLite
                cur = dbapi_conn.cursor()
                cur.execute("PRAGMA foreign_keys=ON")
                cur.close()
        store = HistoryStore(engine, str(db))
        try:
            store._init_schema()
        except BaseException:
            engine.dispose()
            raise
    except sa.exc.SQLAlchemyError as err:
        raise StoreError(f"{db}: cannot open the history database: "
                         f"{str(err).splitlines()[0]}") from None
    except ModuleNotFoundError as err:
        raise StoreError(f"{db}: database driver missing ({err.name}); for PostgreSQL "
                         "install condmon[postgres]") from None
    return store
