"""Reading a history back: a unit's tests as one table, every unit's latest status."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
import sqlalchemy as sa

from condmon.store import schema as S
from condmon.store.base import StoreBase, as_utc, now, utc_column

__all__ = ["ViewsMixin", "ForecastCacheMixin", "test_status", "building_summary", "by_urgency"]


def test_status(role: str, accepted: bool, excluded: bool, status: Any) -> str:
    """What a test row shows: ``excluded``, ``baseline``, ``rejected`` (a
    rejected baseline test), ``retest`` (a rejected check) or the check's
    go / advisory / no-go.

    Example
    -------
    >>> test_status("check", True, False, "no-go"), test_status("check", False, False, None)
    ('no-go', 'retest')
    """
    if excluded:
        return "excluded"
    if role == "baseline":
        return "baseline" if accepted else "rejected"
    if not accepted:
        return "retest"
    return str(status) if isinstance(status, str) else "unchecked"


def building_summary(accepted: int, rejected: str | None = None) -> str:
    """What a unit whose baseline is not saved yet (status ``building``) says:
    how many accepted healthy tests it has, and why its latest was rejected.

    Example
    -------
    >>> building_summary(2)
    'building the baseline: 2 of 3 accepted healthy tests'
    >>> building_summary(1, "fit 42.0 % below 80 %")
    'building the baseline: 1 of 3 accepted healthy tests; latest rejected: fit 42.0 % below 80 %'
    """
    from condmon.monitor.baseline import MIN_BASELINE_TESTS

    text = (f"building the baseline: {accepted} of {MIN_BASELINE_TESTS} accepted healthy tests"
            if accepted < MIN_BASELINE_TESTS else
            f"building the baseline: {accepted} accepted healthy tests, none saved yet")
    return text + (f"; latest rejected: {rejected}" if rejected else "")


def _spread(index: pd.Index, ids: Sequence[int], names: Sequence[str], values: Sequence[Any],
            order: Sequence[str], suffix: str) -> pd.DataFrame:
    """Long rows (test id, parameter, value) as a column ``<parameter><suffix>``
    per parameter of ``order``, on the tests of ``index`` (NaN where a test has
    none; a value that is no number, NaN too).

    Why by hand: ``DataFrame.pivot`` and ``join`` per value column took half of
    a history's read (about 2 ms each, five of them), and a history is read at
    every check."""
    col = {n: j for j, n in enumerate(order)}
    out = np.full((len(index), len(order)), np.nan)
    rows = index.get_indexer(pd.Index(list(ids)))
    cols = np.array([col[n] for n in names], dtype=np.intp)
    try:   # numbers and NULLs (None reads as NaN)
        vals = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):   # text another tool wrote: what reads as a number
        vals = pd.to_numeric(pd.Series(values, dtype=object), errors="coerce").to_numpy(
            dtype=np.float64, na_value=np.nan)
    keep = rows >= 0
    out[rows[keep], cols[keep]] = vals[keep]
    return pd.DataFrame(out, index=index, columns=[f"{n}{suffix}" for n in order])


class ViewsMixin(StoreBase):
    """History tables (part of :class:`HistoryStore`)."""

    def history(self, unit: str) -> pd.DataFrame:
        """One row per test of the unit, oldest first.

        Columns: ``test_id`` (index), ``created_at`` (when stored, UTC),
        ``test_date`` (when run, if known), ``date`` (the test date, else when
        stored), ``source, role, accepted, excluded, excluded_reason, reason,
        fit_percent, fits, method, status`` (see :func:`test_status`),
        ``summary, baseline_id`` (of the evaluation shown: the newest),
        ``regime`` (the operating regime(s) estimated, None without),
        ``hours`` (the unit's operating hours at the test, if given [h]), then
        each parameter's value (a regime's as ``Tc@forward``), ``<param>_se``
        (its standard error) and, for checked tests, ``<param>_change`` [%],
        ``<param>_high``, ``<param>_low``; ``conditions``, when a test has
        any: its operating conditions, ``{name: value}`` [condition units].
        """
        def run(c: sa.Connection) -> tuple[list[Any], list[Any], list[Any]]:
            urow = self._unit_row(c, unit)
            if urow is None:
                raise self._unknown_unit(c, unit)
            t, d, s = S.tests, S.diagnoses, S.symptoms
            # the evaluation against the newest baseline each test was evaluated
            # with, looked up per test of this unit (not grouped over the fleet)
            newest_d, newest_s = d.alias("newest_d"), s.alias("newest_s")
            bid_d = (sa.select(sa.func.max(newest_d.c.baseline_id))
                     .where(newest_d.c.test_id == t.c.id).scalar_subquery())
            base = c.execute(
                sa.select(t.c.id, t.c.created_at, t.c.test_date, t.c.source, t.c.role,
                          t.c.accepted, t.c.excluded, t.c.excluded_reason, t.c.reason,
                          t.c.fit_percent, t.c.fits, t.c.method, d.c.status, d.c.summary,
                          d.c.baseline_id, t.c.regime, t.c.hours, t.c.cycle,
                          t.c.conditions)
                .select_from(t.outerjoin(d, sa.and_(d.c.test_id == t.c.id,
                                                    d.c.baseline_id == bid_d)))
                .where(t.c.unit_id == urow.id).order_by(t.c.id)).all()
            est = c.execute(
                sa.select(S.estimates.c.test_id, S.estimates.c.parameter, S.estimates.c.value,
                          S.estimates.c.std_error, S.estimates.c.systematic)
                .join(t, t.c.id == S.estimates.c.test_id).where(t.c.unit_id == urow.id)).all()
            bid_s = (sa.select(sa.func.max(newest_s.c.baseline_id))
                     .where(newest_s.c.test_id == s.c.test_id).scalar_subquery())
            sym = c.execute(
                sa.select(s.c.test_id, s.c.parameter, s.c.percent_change, s.c.high, s.c.low)
                .select_from(s.join(t, t.c.id == s.c.test_id))
                .where(t.c.unit_id == urow.id, s.c.baseline_id == bid_s)).all()
            return list(base), list(est), list(sym)

        base, est, sym = self._read(run)
        cols = ["test_id", "created_at", "test_date", "source", "role", "accepted", "excluded",
                "excluded_reason", "reason", "fit_percent", "fits", "method", "status",
                "summary", "baseline_id", "regime", "hours", "cycle", "conditions"]
        df = pd.DataFrame(base, columns=cols).set_index("test_id")
        held = df.pop("conditions")
        df["hours"] = pd.to_numeric(df["hours"], errors="coerce")
        df["cycle"] = pd.to_numeric(df["cycle"], errors="coerce")
        df["created_at"] = utc_column(df["created_at"])
        df["test_date"] = utc_column(df["test_date"])
        df.insert(2, "date", df["test_date"].fillna(df["created_at"]))
        df["accepted"] = df["accepted"].astype(bool)
        df["excluded"] = df["excluded"].astype(bool)
        df["status"] = [test_status(r, a, x, s) for r, a, x, s in
                        zip(df["role"], df["accepted"], df["excluded"], df["status"])]
        blocks = []
        if est:
            ids, names, value, se, sys_ = zip(*est)
            order = self._ordered(unit, sorted(set(names)))
            blocks += [_spread(df.index, ids, names, value, order, ""),
                       _spread(df.index, ids, names, se, order, "_se")]
            if any(v is not None and v == v for v in sys_):   # where sensors state an accuracy
                blocks.append(_spread(df.index, ids, names, sys_, order, "_sys"))
        if sym:
            ids, names, change, high, low = zip(*sym)
            order = sorted(set(names))
            blocks += [_spread(df.index, ids, names, v, order, f"_{col}")
                       for col, v in (("change", change), ("high", high), ("low", low))]
        if blocks:
            df = pd.concat([df, *blocks], axis=1)
        if held.notna().any():   # the operating conditions the test was judged at
            from condmon.store.history import condition_pairs

            df["conditions"] = pd.Series(
                [{k: v[0] for k, v in condition_pairs(doc).items()}
                 if isinstance(doc, str) and doc else None   # NULL reads as NaN
                 for doc in held], index=df.index, dtype=object)
        return df


class ForecastCacheMixin(StoreBase):
    """Kept forecasts (schema v6's ``forecasts``): read for many units in two
    queries, written in one transaction."""

    def unit_models(self, units: Sequence[str] | None = None
                    ) -> list[tuple[str, str, str | None]]:
        """Every unit's (or ``units``') name, model (as stored) and group, in one query."""
        u = S.units
        q = sa.select(u.c.name, u.c.model, u.c.group_name)
        if units is not None:
            q = q.where(u.c.name.in_(list(units)))
        return self._read(lambda c: [(str(r[0]), str(r[1]), None if r[2] is None else str(r[2]))
                                     for r in c.execute(q)])

    def kept_forecasts(self, units: Sequence[str] | None = None
                       ) -> dict[str, tuple[int, int, str | None, str | None]]:
        """``{unit: (audit_id, peers, summary JSON, reason)}`` of every kept
        forecast (or ``units``')."""
        f, u = S.forecasts, S.units
        q = sa.select(u.c.name, f.c.audit_id, f.c.peers, f.c.summary, f.c.reason).select_from(
            u.join(f, f.c.unit_id == u.c.id))
        if units is not None:
            q = q.where(u.c.name.in_(list(units)))
        return self._read(lambda c: {str(r[0]): (int(r[1]), int(r[2]), r[3], r[4])
                                     for r in c.execute(q)})

    def kept_rates(self, units: Sequence[str]) -> dict[str, tuple[int, dict[str, Any]]]:
        """``{unit: (audit_id, rates)}`` of the kept degradation rates of ``units``
        (``{"<by>|<parameter>": [rate, se] or None}``), where kept."""
        f, u = S.forecasts, S.units
        q = (sa.select(u.c.name, f.c.audit_id, f.c.rates).select_from(
            u.join(f, f.c.unit_id == u.c.id))
            .where(u.c.name.in_(list(units)), f.c.rates.is_not(None)))
        return self._read(lambda c: {str(r[0]): (int(r[1]), json.loads(r[2]))
                                     for r in c.execute(q)})

    def forecast_method(self) -> int:
        """The forecast method the kept forecasts were made by (0: none
        recorded: made before methods were)."""
        raw = self._read(lambda c: c.execute(sa.select(S.meta.c.value).where(
            S.meta.c.key == "forecast_method")).scalar())
        return int(raw) if raw and str(raw).isdigit() else 0

    def renew_forecasts(self, method: int) -> None:
        """Drop every kept forecast and kept wear (another method made them)
        and record ``method`` as the one kept forecasts are made by."""
        def run(c: sa.Connection) -> None:
            c.execute(sa.delete(S.forecasts))
            c.execute(sa.delete(S.meta).where(S.meta.c.key == "forecast_method"))
            c.execute(sa.insert(S.meta).values(key="forecast_method", value=str(method)))

        self._write(run, lock=None)

    def keep_forecasts(self, rows: Sequence[tuple[Any, ...]]) -> None:
        """Keep ``(unit, audit_id, peers, summary, reason[, rates])`` rows (the
        summary and the unit's degradation rates kept as JSON), replacing the
        units' earlier ones."""
        if not rows:
            return
        f, u = S.forecasts, S.units

        def run(c: sa.Connection) -> None:
            ids = {str(r[0]): int(r[1]) for r in c.execute(
                sa.select(u.c.name, u.c.id).where(u.c.name.in_([r[0] for r in rows])))}
            keep = [r for r in rows if r[0] in ids]
            c.execute(sa.delete(f).where(f.c.unit_id.in_([ids[r[0]] for r in keep])))
            stamp = now()
            c.execute(sa.insert(f), [{"unit_id": ids[n], "audit_id": a, "peers": p,
                                      "computed_at": stamp, "reason": why,
                                      "summary": None if s is None else json.dumps(s),
                                      "rates": (json.dumps(more[0]) if more and more[0]
                                                is not None else None),
                                      **_urgency_columns(s or {})}
                                     for n, a, p, s, why, *more in keep])

        self._write(run, lock=rows[0][0] if len(rows) == 1 else None)


def _urgency_columns(summary: dict[str, Any]) -> dict[str, Any]:
    """A kept forecast's crossing date and median, for ordering in SQL."""
    date = summary.get("date")
    median = summary.get("median")
    when = pd.Timestamp(date).floor("us").to_pydatetime() if date else None  # to the microsecond
    return {"crossing_date": as_utc(when),
            "median": float(median) if isinstance(median, (int, float)) else None}


def _urgency(row: dict[str, Any]) -> tuple[int, float, str]:
    f = row.get("forecast")
    if not f:
        return (3, 0.0, "")
    if f["median"] is None:  # a trend, but most draws never cross
        return (2, 0.0, "")
    if f["date"]:  # days and tests are not one scale: dated forecasts by their date
        return (0, 0.0, str(f["date"]))
    return (1, float(f["median"]), "")


def by_urgency(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Units (rows of :func:`~condmon.store.kept.fleet_summaries`) by their earliest forecast to no-go.

    Dated forecasts first, by their median crossing date; then forecasts in
    tests, by the median tests left; then trends whose median never crosses;
    then the units without a forecast (no trend, too few checks, no
    baseline). Ties keep their order (by name).

    Example
    -------
    >>> rows = [{"unit": "A", "forecast": None},
    ...         {"unit": "B", "forecast": {"median": 9.0, "date": None}},
    ...         {"unit": "C", "forecast": {"median": 4.0, "date": None}},
    ...         {"unit": "D", "forecast": {"median": 30.0, "date": "2026-02-01T00:00:00+00:00"}}]
    >>> [r["unit"] for r in by_urgency(rows)]
    ['D', 'C', 'B', 'A']
    """
    return sorted(rows, key=_urgency)
