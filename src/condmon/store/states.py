"""Every unit's latest status, kept as one row a unit (``unit_states``) so a fleet
of any size is listed, filtered, counted and paged by the database.

A unit's row is worked out again inside every write transaction that changes
the unit (whatever logs an audit row for it marks it), from the unit's own
tests, evaluations, isolations and baselines; a listing then reads rows, not
histories: the cost of a page does not grow with the number of tests, and
counts per status are one aggregate query.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import Any

import sqlalchemy as sa

from condmon.store import schema as S
from condmon.store.base import TOUCHED, StoreBase, as_utc
from condmon.store.isolations import isolation_status
from condmon.store.views import building_summary, test_status

__all__ = ["StatesMixin", "DEGRADED", "STATUS_ORDER", "state_rows"]

#: The statuses that make a unit one that "has degraded" (an accepted check
#: evaluated at one of them): its series teach the fleet prior of its peers.
DEGRADED = ("advisory", "no-go")

#: Statuses by severity, the most urgent first (``none``: nothing stored yet).
STATUS_ORDER = ("no-go", "advisory", "retest", "not judged", "stale", "go", "unchecked",
                "building", "baseline", "rejected", "excluded", "none")

_CHUNK = 500   # unit ids per IN (...) list: well inside every back-end's limit


def _chunks(ids: Sequence[int]) -> Iterable[list[int]]:
    for i in range(0, len(ids), _CHUNK):
        yield list(ids[i:i + _CHUNK])


def state_rows(conn: sa.Connection, uids: Sequence[int] | None) -> list[dict[str, Any]]:
    """The ``unit_states`` rows of units ``uids`` (None: every unit), worked out
    from their histories in a few queries (each unit's latest test, isolation and
    baseline version are ranked in the database)."""
    if uids is None:
        return _state_rows(conn, None)
    return [row for chunk in _chunks(sorted(set(uids))) for row in _state_rows(conn, chunk)]


def _state_rows(conn: sa.Connection, uids: list[int] | None) -> list[dict[str, Any]]:
    t, i, d, b, a = S.tests, S.isolations, S.diagnoses, S.baselines, S.audit

    def only(q: Any, col: Any) -> Any:
        return q if uids is None else q.where(col.in_(uids))

    u = S.units
    healthy = sa.and_(t.c.role == "baseline", t.c.accepted.is_(True), t.c.excluded.is_(False))

    def per_unit(q: Any) -> Any:
        return q.scalar_subquery()

    # each unit's counts, newest rows, saved baseline and whether it has degraded: one
    # query (correlated look-ups through the indexes by unit)
    units = conn.execute(only(sa.select(
        u.c.id,
        per_unit(sa.select(sa.func.count()).where(t.c.unit_id == u.c.id)),
        per_unit(sa.select(sa.func.count()).where(t.c.unit_id == u.c.id, healthy)),
        per_unit(sa.select(sa.func.max(t.c.id)).where(t.c.unit_id == u.c.id)),
        per_unit(sa.select(sa.func.count()).where(i.c.unit_id == u.c.id)),
        per_unit(sa.select(sa.func.max(i.c.id)).where(i.c.unit_id == u.c.id)),
        sa.exists().where(b.c.unit_id == u.c.id,
                          b.c.name == sa.func.coalesce(u.c.baseline_name, "default")),
        per_unit(sa.select(sa.func.max(b.c.id)).where(b.c.unit_id == u.c.id)),
        sa.exists().where(t.c.unit_id == u.c.id, t.c.role == "check", t.c.accepted.is_(True),
                          t.c.excluded.is_(False), d.c.test_id == t.c.id,
                          d.c.status.in_(DEGRADED)),
        per_unit(sa.select(sa.func.max(a.c.id)).where(a.c.unit_id == u.c.id))), u.c.id)).all()
    t_when = sa.func.coalesce(t.c.test_date, t.c.created_at)
    # a unit's status is its latest check's; baseline tests only without checks. The
    # latest by test date when every check carries one (a record checked late goes
    # where it was tested), else the last stored (an undated check's storing time is
    # not when it was tested), as its forecast orders them
    dated = only(sa.select(t.c.unit_id, sa.func.min(sa.case((t.c.test_date.is_(None), 0),
                                                            else_=1)).label("all"))
                 .where(t.c.excluded.is_(False), t.c.role == "check"), t.c.unit_id
                 ).group_by(t.c.unit_id).subquery()
    # shown as the latest date: an imported row's own date only (its storing time
    # is when the table was read, not when the value was measured: none, for a
    # table counted in cycles or hours)
    shown = sa.case((t.c.method == "import", t.c.test_date), else_=t_when)
    ranked = only(sa.select(t.c.unit_id, t.c.id, t.c.source, t.c.role, t.c.accepted,
                            t.c.excluded, shown.label("at"), t.c.reason, t.c.regime,
                            sa.func.row_number().over(
                                partition_by=t.c.unit_id,
                                order_by=((t.c.role == "check").desc(),
                                          sa.case((dated.c.all == 1, t_when)).desc(),
                                          t.c.id.desc())).label("rank"))
                  .select_from(t.outerjoin(dated, dated.c.unit_id == t.c.unit_id))
                  .where(t.c.excluded.is_(False)), t.c.unit_id).subquery()
    newest = d.alias("newest")   # the evaluation against the newest baseline evaluated with
    latest_bid = (sa.select(sa.func.max(newest.c.baseline_id))
                  .where(newest.c.test_id == ranked.c.id).scalar_subquery())
    last = {r[0]: r[1:] for r in conn.execute(
        sa.select(ranked.c.unit_id, ranked.c.id, ranked.c.source, ranked.c.role,
                  ranked.c.accepted, ranked.c.excluded, d.c.status, ranked.c.at,
                  d.c.summary, ranked.c.reason, ranked.c.regime)
        .select_from(ranked.outerjoin(d, sa.and_(d.c.test_id == ranked.c.id,
                                                 d.c.baseline_id == latest_bid)))
        .where(ranked.c.rank == 1))}
    i_when = sa.func.coalesce(i.c.test_date, i.c.created_at)
    iranked = only(sa.select(i.c.unit_id, i.c.id, i.c.source, i.c.detected, i.c.decided,
                             i.c.statement, i_when.label("at"),
                             sa.func.row_number().over(
                                 partition_by=i.c.unit_id,
                                 order_by=(i_when.desc(), i.c.id.desc())).label("rank"))
                   .where(i.c.excluded.is_(False)), i.c.unit_id).subquery()
    isos = {r[0]: r[1:] for r in conn.execute(
        sa.select(*[col for col in iranked.c if col.name != "rank"]).where(iranked.c.rank == 1))}
    out = []
    for uid, n, accepted, last_test, n_iso, last_iso, saved, last_baseline, degraded, mark \
            in units:
        test, iso = last.get(uid), isos.get(uid)
        status, source, when, summary, regime = None, None, None, None, None
        if test is not None:
            status = test_status(test[2], bool(test[3]), bool(test[4]), test[5])
            source, when, regime = test[1], test[6], test[9] or None
            summary = test[7] if test[3] else test[8]
            if status in ("baseline", "rejected") and not saved:
                status = "building"
                summary = building_summary(int(accepted), None if test[3] else test[8])
        if iso is not None and (when is None or _after(iso[5], when)):
            status = isolation_status(bool(iso[2]), bool(iso[3]))
            source, when, summary, regime = iso[1], iso[5], iso[4], None
        out.append({"unit_id": uid, "mark": int(mark or 0), "status": status,
                    "latest_source": source, "latest_date": as_utc(when),
                    "summary": summary, "latest_regime": regime, "tests": int(n),
                    "isolations": int(n_iso), "degraded": bool(degraded),
                    "last_test": last_test, "last_isolation": last_iso,
                    "last_baseline": last_baseline})
    return out


def _after(a: Any, b: Any) -> bool:
    ta, tb = as_utc(a), as_utc(b)
    return ta is not None and tb is not None and ta >= tb


def write_states(conn: sa.Connection, uids: Sequence[int] | None = None) -> None:
    """Work out the state rows of ``uids`` (None: every unit) and replace theirs."""
    rows = state_rows(conn, uids)
    st = S.unit_states
    if uids is None:
        conn.execute(sa.delete(st))
    else:
        for chunk in _chunks(sorted(set(uids))):
            conn.execute(sa.delete(st).where(st.c.unit_id.in_(chunk)))
    if rows:
        conn.execute(sa.insert(st), rows)


def stale_units(conn: sa.Connection) -> list[int]:
    """Units whose state row is missing or older than their rows: tests,
    isolations or baselines added by another tool (not through the store), found from the
    newest ids (a few index look-ups when nothing is stale)."""
    st, u = S.unit_states, S.units
    pairs = ((S.tests, st.c.last_test), (S.isolations, st.c.last_isolation),
             (S.baselines, st.c.last_baseline))
    # one look-up when nothing is stale: units without a row, the newest ids seen and stored
    first = conn.execute(sa.select(
        sa.exists(sa.select(u.c.id).where(~sa.exists().where(st.c.unit_id == u.c.id))),
        *[sa.select(sa.func.max(col)).scalar_subquery() for _, col in pairs],
        *[sa.select(sa.func.max(table.c.id)).scalar_subquery() for table, _ in pairs])).one()
    found: set[int] = set()
    if first[0]:
        found |= {r[0] for r in conn.execute(
            sa.select(u.c.id).where(~sa.exists().where(st.c.unit_id == u.c.id)))}
    for k, (table, _) in enumerate(pairs):
        seen, top = first[1 + k], first[4 + k]
        if top is not None and (seen is None or top > seen):
            found |= {r[0] for r in conn.execute(
                sa.select(table.c.unit_id).distinct().where(table.c.id > (seen or 0)))}
    return sorted(found)


def _severity() -> Any:
    st = S.unit_states
    return sa.case({s: k for k, s in enumerate(STATUS_ORDER)},
                   value=sa.func.coalesce(st.c.status, "none"), else_=len(STATUS_ORDER))


class StatesMixin(StoreBase):
    """Every unit's latest status (part of :class:`HistoryStore`)."""

    def _settle(self, conn: sa.Connection) -> None:
        """The state rows of the units the transaction on ``conn`` changed, worked
        out again before it commits."""
        touched = conn.info.pop(TOUCHED, None)
        if touched:
            write_states(conn, sorted(touched))

    _COLUMNS = ("status", "latest_source", "latest_date", "summary", "latest_regime", "tests",
                "isolations")

    def _summary_query(self) -> Any:
        u, st = S.units, S.unit_states
        return (sa.select(u.c.name, u.c.model, u.c.model_source, u.c.group_name,
                          *[st.c[c] for c in self._COLUMNS])
                .select_from(u.outerjoin(st, st.c.unit_id == u.c.id)))

    def _summaries(self, rows: Iterable[Any]) -> list[dict[str, Any]]:
        out = []
        for row in rows:
            r = row if isinstance(row, dict) else row._mapping
            stamp = as_utc(r["latest_date"])
            out.append({"unit": r["name"], "model": r["model"],
                        "model_source": r["model_source"],
                        "tests": int(r["tests"] or 0), "isolations": int(r["isolations"] or 0),
                        "latest_source": r["latest_source"],
                        "latest_date": None if stamp is None else stamp.isoformat(),
                        "status": r["status"], "summary": r["summary"],
                        "latest_regime": r["latest_regime"], "group": r["group_name"]})
        return out

    def refresh_states(self) -> int:
        """Work out again the state rows of the units another tool changed (rows
        added without the store); returns how many. A history opened read-only
        raises :class:`~condmon.store.engine.StoreError`."""
        def run(conn: sa.Connection) -> int:
            stale = stale_units(conn)
            if stale:
                write_states(conn, stale)
            return len(stale)

        if not self._read(stale_units):
            return 0
        return self._write(run, lock=None)

    def states_current(self) -> bool:
        """Whether every unit's state row is current, after bringing the stale ones
        up to date when the history can be written (False when it cannot)."""
        from condmon.store.engine import StoreError

        try:
            self.refresh_states()
        except StoreError:
            return False
        return True

    def _with_flags(self, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """``rows`` with their active baselines' flags (``baseline_flags``: how
        many, one query) and their groups' (``group_flags``), read now: flags
        are kept with the baselines, which may change under the kept rows."""
        b, u = S.baselines, S.units
        names = [str(r["unit"]) for r in rows]
        ranked = (sa.select(u.c.name, b.c.flags, sa.func.row_number().over(
            partition_by=b.c.unit_id, order_by=b.c.version.desc()).label("rank"))
            .select_from(u.join(b, sa.and_(b.c.unit_id == u.c.id,
                                           b.c.name == sa.func.coalesce(u.c.baseline_name,
                                                                        "default")))))
        if len(names) <= _CHUNK:   # a page's units; more: every unit's, then picked
            ranked = ranked.where(u.c.name.in_(names))
        sub = ranked.subquery()
        q = sa.select(sub.c.name, sub.c.flags).where(sub.c.rank == 1)
        flags_of = {str(r[0]): r[1] for r in self._read(lambda c: c.execute(q).all())}
        for r in rows:
            flags = flags_of.get(str(r["unit"]))
            r["baseline_flags"] = len(json.loads(flags)) if flags else 0
        groups = {str(r["group"]) for r in rows if r["group"]}
        unlike = self.group_flags(groups) if groups else {}  # type: ignore[attr-defined]
        for r in rows:
            r["group_flags"] = unlike.get(str(r["unit"]), [])
        return rows

    def unit_summaries(self, units: Sequence[str] | None = None) -> list[dict[str, Any]]:
        """Every unit (or ``units`` alone), by name, with its model, number of
        tests and isolations, its latest test or isolation (by date), that
        one's status and operating regime (``latest_regime``), its ``group``
        and where its own baseline lies outside its peers' spread
        (``group_flags``), and the active baseline's flags (``baseline_flags``:
        how many warnings).

        A unit whose latest record is a baseline test while no version of its
        active baseline is saved yet is ``building`` (as ``condmon fleet run``
        says), its summary how far (:func:`building_summary`). One query
        however many tests there are (the kept state rows).
        """
        q = self._summary_query().add_columns(S.units.c.id).order_by(S.units.c.name)
        if units is not None:
            q = q.where(S.units.c.name.in_(list(units)))

        def run(c: sa.Connection) -> list[dict[str, Any]]:
            rows: list[Any] = list(c.execute(q).all())
            stale = stale_units(c)
            if stale:   # rows another tool added: worked out here (the history may be read-only)
                fresh = {r["unit_id"]: r for r in state_rows(c, stale)}
                rows = [{**r._mapping, **{k: fresh[r.id][k] for k in self._COLUMNS}}
                        if r.id in fresh else r for r in rows]
            return self._summaries(rows)

        return self._with_flags(self._read(run))

    def status_counts(self) -> dict[str, int]:
        """Units per latest status (``none``: nothing stored yet), one aggregate query."""
        u, st = S.units, S.unit_states
        status = sa.func.coalesce(st.c.status, "none")
        q = (sa.select(status, sa.func.count()).select_from(u.outerjoin(st, st.c.unit_id == u.c.id))
             .group_by(status))
        return self._read(lambda c: {str(r[0]): int(r[1]) for r in c.execute(q)})

    def _filtered(self, q: Any, statuses: Sequence[str], text: str) -> Any:
        u, st = S.units, S.unit_states
        if statuses:
            q = q.where(sa.func.coalesce(st.c.status, "none").in_(list(statuses)))
        if text:
            q = q.where(sa.func.lower(u.c.name).contains(text.lower(), autoescape=True))
        return q

    def count_units(self, statuses: Sequence[str] = (), text: str = "") -> int:
        """How many units pass the filter of :meth:`unit_page`."""
        u, st = S.units, S.unit_states
        q = self._filtered(sa.select(sa.func.count()).select_from(
            u.outerjoin(st, st.c.unit_id == u.c.id)), statuses, text)
        return int(self._read(lambda c: c.execute(q).scalar()) or 0)

    def unit_page(self, statuses: Sequence[str] = (), text: str = "", sort: str = "name",
                  offset: int = 0, limit: int | None = None) -> list[dict[str, Any]]:
        """One page of :meth:`unit_summaries`, filtered, ordered and cut by the database.

        Parameters
        ----------
        statuses : sequence of str
            Keep the units whose latest status is one of these (``none``:
            nothing stored). Empty: all.
        text : str
            Keep the units whose name contains it (any case; ASCII letters).
        sort : {"name", "status", "date"}
            By name; by status, the most severe first (:data:`STATUS_ORDER`),
            then by name; by latest date, the newest first.
        offset, limit : int
            Skip ``offset`` units, then give ``limit`` (None: the rest).
        """
        u, st = S.units, S.unit_states
        order = {"name": (u.c.name,), "status": (_severity(), u.c.name),
                 "date": (st.c.latest_date.is_(None), st.c.latest_date.desc(), u.c.name)}[sort]
        q = self._filtered(self._summary_query(), statuses, text).order_by(*order).offset(offset)
        if limit is not None:
            q = q.limit(limit)
        return self._with_flags(self._read(lambda c: self._summaries(c.execute(q))))

    def units_with_status(self, statuses: tuple[str, ...] = DEGRADED
                          ) -> dict[str, tuple[str, str | None]]:
        """Units that have degraded (an accepted, not excluded check evaluated
        advisory or no-go, :data:`DEGRADED`), each with its model and group,
        from the kept state rows in one query."""
        if tuple(statuses) != DEGRADED:
            raise ValueError(f"only the degraded statuses {DEGRADED} are kept per unit")
        u = S.units
        q = self._degraded_rows(u.c.name, u.c.model, u.c.group_name)
        return self._read(lambda c: {str(r[0]): (str(r[1]), None if r[2] is None else str(r[2]))
                                     for r in c.execute(q)})

    def _degraded_rows(self, *columns: Any) -> Any:
        u, st = S.units, S.unit_states
        return (sa.select(*columns).select_from(u.join(st, st.c.unit_id == u.c.id))
                .where(st.c.degraded.is_(True)))

    def degraded_counts(self) -> dict[tuple[str, str | None], int]:
        """How many units have degraded, by model and group: one aggregate over
        the kept state rows (a few rows, whatever the fleet's size)."""
        u = S.units
        q = self._degraded_rows(u.c.model, u.c.group_name, sa.func.count()) \
            .group_by(u.c.model, u.c.group_name)
        return self._read(lambda c: {(str(r[0]), None if r[1] is None else str(r[1])): int(r[2])
                                     for r in c.execute(q)})

    def degraded_among(self, units: Sequence[str]) -> set[str]:
        """Those of ``units`` that have degraded."""
        q = self._degraded_rows(S.units.c.name).where(S.units.c.name.in_(list(units)))
        return self._read(lambda c: {str(r[0]) for r in c.execute(q)}) if units else set()

    def recent_degraded(self, model: str, group: str | None, limit: int) -> list[str]:
        """The ``limit`` degraded units of ``model`` (and ``group``; None: any)
        whose history changed last (their latest audit row), newest first."""
        u, st = S.units, S.unit_states
        q = self._degraded_rows(u.c.name).where(u.c.model == model)
        if group is not None:
            q = q.where(u.c.group_name == group)
        q = q.order_by(sa.func.coalesce(st.c.mark, 0).desc(), u.c.name).limit(limit)
        return self._read(lambda c: [str(r[0]) for r in c.execute(q)])

    def history_marks(self, units: Sequence[str] | None = None) -> dict[str, int]:
        """Each unit's latest audit row (or ``units``' alone; a name: that unit's): it
        changes whenever the unit's history does."""
        u, st = S.units, S.unit_states
        q = sa.select(u.c.name, st.c.mark).select_from(u.join(st, st.c.unit_id == u.c.id))
        if units is not None:
            q = q.where(u.c.name.in_([units] if isinstance(units, str) else list(units)))
        return self._read(lambda c: {str(r[0]): int(r[1]) for r in c.execute(q) if r[1]})
