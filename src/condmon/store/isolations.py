"""Fault isolations of plant-model units (``condmon isolate --unit``) in the history."""

from __future__ import annotations

import json
from datetime import datetime
from typing import Any

import pandas as pd
import sqlalchemy as sa

from condmon.errors import ConfigError
from condmon.store import schema as S
from condmon.store.base import StoreBase, as_utc, check_name, now, num, utc_column
from condmon.store.history import DuplicateTestError

__all__ = ["IsolationsMixin", "isolation_status", "isolation_values", "isolation_estimate_rows"]


def isolation_status(detected: bool, decided: bool) -> str:
    """The operator's status of an isolation: ``go`` (no fault detected),
    ``no-go`` (a fault detected, isolated or not) or ``retest`` (undecided).

    Example
    -------
    >>> isolation_status(True, True), isolation_status(False, False)
    ('no-go', 'retest')
    """
    if not decided and not detected:
        return "retest"
    return "no-go" if detected else "go"


def isolation_values(result: Any, model: str, source: str, digest: str, file_digest: str,
                     test_date: datetime | None, fingerprint: str | None) -> dict[str, Any]:
    """An isolation's ``isolations`` row but its ``unit_id`` (see
    :meth:`IsolationsMixin.add_isolation`)."""
    return dict(
        created_at=now(), test_date=as_utc(test_date), source=source, file_hash=file_digest,
        record_hash=digest, fingerprint=fingerprint, model=model,
        detected=bool(result.detected), detection_time=num(result.detection_time),
        decided=bool(result.decided), reason=result.reason, statement=result.statement,
        suspects=json.dumps(list(result.suspects)), isolated=json.dumps(list(result.isolated)),
        result=json.dumps(result.to_dict(), default=str))


def isolation_estimate_rows(iid: Any, result: Any) -> list[dict[str, Any]]:
    """``isolation_estimates`` rows of isolation ``iid``."""
    return [{"isolation_id": iid, "parameter": p, "value": num(e.value),
             "nominal": num(e.nominal), "change_percent": num(e.change_percent),
             "error_sigma": num(result.errors.get(p)), "rejected": result.rejected.get(p)}
            for p, e in result.estimates.items()]


class IsolationsMixin(StoreBase):
    """Isolations (part of :class:`HistoryStore`)."""

    def add_isolation(self, unit: str, result: Any, *, model: str, source: str, digest: str,
                      file_digest: str | None = None, test_date: datetime | None = None,
                      model_source: str | None = None, fingerprint: str | None = None) -> int:
        """Store one isolation (detection, suspects, estimates, statement).

        Parameters
        ----------
        unit : str
            Unit name (created on first use, with ``model``).
        result : IsolationResult
        model : str
            The plant model's name.
        source : str
            The record's file.
        digest : str
            Content hash of the record; the same data twice is refused.
        file_digest : str, optional
        test_date : datetime, optional
        model_source : str, optional
            The declaration file, when the model is not a shipped one.
        fingerprint : str, optional
            :func:`condmon.io.digest.fingerprint` of the record (a copy rounded
            otherwise is the same record).

        Returns
        -------
        int
            The isolation's id.

        Raises
        ------
        DuplicateTestError
            The record is already among the unit's isolations.
        """
        check_name(unit)
        fdig = file_digest or digest

        def run(conn: sa.Connection) -> int:
            uid = self.unit_id(unit, create=True, model=model, conn=conn,
                               model_source=model_source)
            i = S.isolations
            dup = self._copy_of(conn, i, uid, digest, fdig, fingerprint)
            if dup is not None:
                raise DuplicateTestError(f"{source}: already in the history of {unit!r} "
                                         f"(isolation #{dup[0]}); not added again", int(dup[0]))
            iid = int(conn.execute(sa.insert(i).values(
                unit_id=uid, **isolation_values(result, model, source, digest, fdig, test_date,
                                                fingerprint))).inserted_primary_key[0])  # type: ignore[index]
            rows = isolation_estimate_rows(iid, result)
            if rows:
                conn.execute(sa.insert(S.isolation_estimates), rows)
            self._log(conn, "isolation added", unit_id=uid, isolation_id=iid,
                      detail={"source": source, "statement": result.statement})
            return iid

        return self._write(run, lock=unit)

    def isolation_copies_elsewhere(self, unit: str, digest: str) -> list[tuple[str, int]]:
        """``(unit, isolation id)`` of the isolations of *other* units with this
        content hash (as :meth:`copies_elsewhere` for tests)."""
        return self._copies_elsewhere(S.isolations, unit, digest)

    def isolation_info(self, isolation_id: int) -> dict[str, Any]:
        """One isolation's ``id, unit_id, unit, source, excluded, excluded_reason``.

        Raises
        ------
        ConfigError
            No such isolation.
        """
        def run(c: sa.Connection) -> Any:
            i = S.isolations
            return c.execute(sa.select(i.c.id, i.c.unit_id, S.units.c.name.label("unit"),
                                       i.c.source, i.c.excluded, i.c.excluded_reason)
                             .join(S.units, S.units.c.id == i.c.unit_id)
                             .where(i.c.id == int(isolation_id))).mappings().first()

        row = self._read(run)
        if row is None:
            raise ConfigError(f"no isolation i{isolation_id} in {self.url} (`condmon history "
                              "--unit U` lists a unit's isolations)")
        return dict(row)

    def set_isolation_excluded(self, isolation_id: int, excluded: bool,
                               reason: str | None) -> dict[str, Any]:
        """Exclude an isolation from the unit's status, trends and reports (or
        include it again); nothing is deleted, the change is audited. Returns the
        isolation's row as it was before."""
        info = self.isolation_info(isolation_id)

        def run(conn: sa.Connection) -> None:
            conn.execute(sa.update(S.isolations).where(S.isolations.c.id == int(isolation_id))
                         .values(excluded=bool(excluded),
                                 excluded_reason=reason if excluded else None))
            self._log(conn, "isolation excluded" if excluded else "isolation included",
                      unit_id=int(info["unit_id"]), isolation_id=int(isolation_id),
                      reason=reason, detail={"source": info["source"]})

        self._write(run, lock=str(info["unit"]))
        return info

    def isolations(self, unit: str) -> pd.DataFrame:
        """One row per isolation of the unit, oldest first.

        Columns: ``isolation_id`` (index), ``created_at, test_date, date`` (the
        test date, else when stored), ``source, detected, detection_time,
        decided, status, reason, statement, suspects, isolated, excluded``, then
        for each suspect ever estimated ``<p>`` (estimate), ``<p>_nominal``
        (the value it was compared with), ``<p>_change`` [%], ``<p>_error``
        (model output error [noise sd]) and ``<p>_rejected`` (left out of the
        comparison: implausible, not converged, ...). Estimates and nominals
        are in the unit the model declares for the parameter.
        """
        def run(c: sa.Connection) -> tuple[list[Any], list[Any]]:
            urow = self._unit_row(c, unit)
            if urow is None:
                raise self._unknown_unit(c, unit)
            i = S.isolations
            base = c.execute(sa.select(i.c.id, i.c.created_at, i.c.test_date, i.c.source,
                                       i.c.detected, i.c.detection_time, i.c.decided,
                                       i.c.reason, i.c.statement, i.c.suspects, i.c.isolated,
                                       i.c.excluded)
                             .where(i.c.unit_id == urow.id).order_by(i.c.id)).all()
            est = c.execute(sa.select(S.isolation_estimates.c.isolation_id,
                                      S.isolation_estimates.c.parameter,
                                      S.isolation_estimates.c.value,
                                      S.isolation_estimates.c.nominal,
                                      S.isolation_estimates.c.change_percent,
                                      S.isolation_estimates.c.error_sigma,
                                      S.isolation_estimates.c.rejected.isnot(None))
                            .join(i, i.c.id == S.isolation_estimates.c.isolation_id)
                            .where(i.c.unit_id == urow.id)).all()
            return list(base), list(est)

        base, est = self._read(run)
        cols = ["isolation_id", "created_at", "test_date", "source", "detected",
                "detection_time", "decided", "reason", "statement", "suspects", "isolated",
                "excluded"]
        df = pd.DataFrame(base, columns=cols).set_index("isolation_id")
        df["created_at"] = utc_column(df["created_at"])
        df["test_date"] = utc_column(df["test_date"])
        df["date"] = df["test_date"].fillna(df["created_at"])
        df["status"] = [isolation_status(bool(d), bool(k))
                        for d, k in zip(df["detected"], df["decided"])]
        for col in ("suspects", "isolated"):
            df[col] = [json.loads(v) for v in df[col]]
        if est:
            e = pd.DataFrame(est, columns=["isolation_id", "parameter", "value", "nominal",
                                           "change", "error", "rejected"])
            for col, suffix in (("value", ""), ("nominal", "_nominal"), ("change", "_change"),
                                ("error", "_error"), ("rejected", "_rejected")):
                w = e.pivot(index="isolation_id", columns="parameter", values=col)
                w.columns = [f"{c}{suffix}" for c in w.columns]
                df = df.join(w)
        return df
