"""Baselines as named, versioned sets of tests (nothing is overwritten)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from condmon.errors import DataError
from condmon.monitor.baseline import MIN_BASELINE_TESTS, Baseline, make_baseline
from condmon.store import schema as S
from condmon.store.base import StoreBase, as_utc, check_name, model_order, now
from condmon.store.engine import StoreError

if TYPE_CHECKING:
    from condmon.store.db import HistoryStore

__all__ = ["BaselinesMixin", "StoredBaseline", "DEFAULT_BASELINE", "id_runs", "baseline_members",
           "current_baseline", "stored_baseline", "baseline_value_rows", "members_of", "too_few_tests"]

#: Name of a unit's baseline until another is chosen.
DEFAULT_BASELINE = "default"


def id_runs(ids: Any) -> str:
    """Test ids as runs: ``#1-#5,#8`` for 1, 2, 3, 4, 5, 8.

    Example
    -------
    >>> id_runs([8, 3, 1, 2, 4, 5])
    '#1-#5,#8'
    """
    runs: list[list[int]] = []
    for i in sorted(int(x) for x in ids):
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    return ",".join(f"#{a}" if a == b else f"#{a}-#{b}" for a, b in runs)


@dataclass(frozen=True)
class StoredBaseline:
    """One version of a unit's named baseline.

    Attributes
    ----------
    id : int
    unit, name : str
    version : int
        1, 2, ... within the name.
    created_at : datetime
        UTC.
    test_ids : tuple of int
        The tests it is computed from.
    baseline : Baseline
        Mean and sample standard deviation of each parameter. [parameter units]
    reason : str or None
        Why this version was made.
    flags : tuple of dict
        Warnings found when it was made (``{"kind", "parameter", "tests", "message"}``):
        robust outliers, a spread far above the estimates' own standard errors.
    """

    id: int
    unit: str
    name: str
    version: int
    created_at: datetime
    test_ids: tuple[int, ...]
    baseline: Baseline
    reason: str | None
    flags: tuple[dict[str, Any], ...]

    def regime_counts(self, history: Any = None) -> dict[str, int]:
        """The tests it holds per operating regime (``{}`` without regimes).

        Parameters
        ----------
        history : DataFrame, optional
            The unit's :meth:`HistoryStore.history`: then its tests are counted
            in every regime they were estimated in, also one with too few of
            them for a baseline (which its statistics leave out).

        Returns
        -------
        dict of str to int
            Regime to number of tests, in the order they first appear.
        """
        from condmon.models.regimes import split_key

        counts = self.baseline.regime_counts()
        if history is None or not len(history):
            return counts
        members = history[history.index.isin(self.test_ids)]
        keys = [c for c in members.columns if f"{c}_se" in members.columns and split_key(c)[1]]
        for regime in dict.fromkeys(split_key(c)[1] for c in keys):
            cols = [c for c in keys if split_key(c)[1] == regime]
            counts[regime] = max(counts.get(regime, 0), int(members[cols].notna().any(
                axis=1).sum()))
        return counts

    def describe(self, history: Any = None) -> str:
        """Which baseline this is and what it holds, in one line.

        Parameters
        ----------
        history : DataFrame, optional
            The unit's history, to count a regime with too few tests for a
            baseline too (:meth:`regime_counts`); such a regime is named as
            one with too few tests to compare.

        Example
        -------
        >>> from datetime import timezone
        >>> b = StoredBaseline(3, "A1", "default", 2, datetime(2026, 5, 1, 8, 0,
        ...                    tzinfo=timezone.utc), tuple(range(1, 11)),
        ...                    Baseline(("Tc@forward", "Tc@reverse"), (39.5, 39.5),
        ...                             (0.2, 0.4), 10, (5, 5)), None, ())
        >>> b.describe()
        'baseline default v2, built 2026-05-01 08:00 UTC from tests #1-#10 (10 tests: forward 5, reverse 5)'
        """
        from condmon.models.regimes import split_key

        n = len(self.test_ids)
        held = f"{n} test{'s' if n != 1 else ''}"
        kept = {split_key(k)[1] for k in self.baseline.parameters}
        counts = self.regime_counts(history)
        if counts:
            held += ": " + ", ".join(f"{r} {c}" for r, c in counts.items())
        few = [r for r in counts if r not in kept]
        if few:
            held += f"; too few to compare {' and '.join(few)}"
        return (f"baseline {self.name} v{self.version}, built "
                f"{self.created_at.astimezone(timezone.utc):%Y-%m-%d %H:%M} UTC from tests "
                f"{id_runs(self.test_ids)} ({held})")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"id": self.id, "name": self.name, "version": self.version,
                "created_at": self.created_at.isoformat(), "test_ids": list(self.test_ids),
                "reason": self.reason, "flags": list(self.flags), **self.baseline.to_dict()}


class BaselinesMixin(StoreBase):
    """Baseline versions (part of :class:`HistoryStore`)."""

    def active_baseline_name(self, unit: str) -> str:
        """The name of the baseline checks of ``unit`` are compared with."""
        def run(c: sa.Connection) -> str:
            row = self._unit_row(c, unit)
            if row is None:
                raise self._unknown_unit(c, unit)
            return str(row.baseline_name or DEFAULT_BASELINE)

        return self._read(run)

    def save_baseline(self, unit: str, baseline: Baseline, test_ids: Sequence[int], *,
                      name: str | None = None, reason: str | None = None,
                      flags: Sequence[dict[str, Any]] = (), activate: bool = True) -> int:
        """Store a baseline version; returns its id.

        ``name`` None: the unit's active baseline. When the latest version of
        that name has the same tests, its id is returned and nothing is
        written; otherwise a new version is added (and, with ``activate``, the
        name becomes the unit's active baseline). Audited.
        """
        ids = sorted({int(i) for i in test_ids})
        doc = json.dumps(ids)
        if name is not None:
            check_name(name, "baseline name", limit=64)
        flag_doc = json.dumps(list(flags), default=str)

        def run(conn: sa.Connection) -> int:
            uid = self.unit_id(unit, create=True, conn=conn)
            urow = conn.execute(sa.select(S.units.c.baseline_name)
                                .where(S.units.c.id == uid)).first()
            label = name or (urow[0] if urow is not None else None) or DEFAULT_BASELINE
            b = S.baselines
            last = conn.execute(sa.select(b.c.id, b.c.test_ids, b.c.version)
                                .where(b.c.unit_id == uid, b.c.name == label)
                                .order_by(b.c.version.desc()).limit(1)).first()
            if activate and urow is not None and urow[0] != label:
                conn.execute(sa.update(S.units).where(S.units.c.id == uid)
                             .values(baseline_name=label))
                self._log(conn, "baseline chosen", unit_id=uid, reason=reason,
                          detail={"name": label})
            if last is not None and json.loads(last[1]) == ids:
                return int(last[0])
            version = 1 if last is None else int(last[2]) + 1
            res = conn.execute(sa.insert(b).values(
                unit_id=uid, created_at=now(), n=int(baseline.n), test_ids=doc, name=label,
                version=version, reason=reason, flags=flag_doc))
            bid = int(res.inserted_primary_key[0])  # type: ignore[index]
            conn.execute(sa.insert(S.baseline_values), baseline_value_rows(bid, baseline))
            self._log(conn, "baseline saved", unit_id=uid, baseline_id=bid, reason=reason,
                      detail={"name": label, "version": version, "test_ids": ids,
                              "flags": len(flags)})
            return bid

        return self._write(run, lock=unit)

    def _stored(self, conn: sa.Connection, unit: str, row: Any) -> StoredBaseline:
        vals = conn.execute(sa.select(S.baseline_values.c.parameter, S.baseline_values.c.mean,
                                      S.baseline_values.c.std, S.baseline_values.c.n)
                            .where(S.baseline_values.c.baseline_id == row.id)).all()
        urow = conn.execute(sa.select(S.units.c.model, S.units.c.model_source)
                            .where(S.units.c.name == unit)).first()
        # the unit's model as it was named: a baseline's values need no declaration
        model = None if urow is None else str(urow[1] or urow[0])
        return stored_baseline(unit, model, row, [tuple(v) for v in vals])

    def baselines(self, unit: str) -> list[StoredBaseline]:
        """Every version of every named baseline of the unit, oldest first."""
        def run(c: sa.Connection) -> list[StoredBaseline]:
            urow = self._unit_row(c, unit)
            if urow is None:
                raise self._unknown_unit(c, unit)
            rows = c.execute(sa.select(S.baselines).where(S.baselines.c.unit_id == urow.id)
                             .order_by(S.baselines.c.id)).all()
            return [self._stored(c, unit, r) for r in rows]

        return self._read(run)

    def baseline_by_id(self, unit: str, baseline_id: int) -> StoredBaseline:
        """The stored baseline version ``baseline_id`` of the unit.

        Raises
        ------
        StoreError
            No such version for this unit.
        """
        def run(c: sa.Connection) -> StoredBaseline:
            urow = self._unit_row(c, unit)
            if urow is None:
                raise self._unknown_unit(c, unit)
            row = c.execute(sa.select(S.baselines)
                            .where(S.baselines.c.unit_id == urow.id,
                                   S.baselines.c.id == int(baseline_id))).first()
            if row is None:
                raise StoreError(f"unit {unit!r} has no baseline with id {baseline_id}")
            return self._stored(c, unit, row)

        return self._read(run)

    def latest_baseline(self, unit: str, name: str | None = None) -> StoredBaseline | None:
        """The latest version of ``name`` (default: the unit's active baseline), or None."""
        def run(c: sa.Connection) -> StoredBaseline | None:
            urow = self._unit_row(c, unit)
            if urow is None:
                raise self._unknown_unit(c, unit)
            label = name or urow.baseline_name or DEFAULT_BASELINE
            row = c.execute(sa.select(S.baselines)
                            .where(S.baselines.c.unit_id == urow.id, S.baselines.c.name == label)
                            .order_by(S.baselines.c.version.desc()).limit(1)).first()
            return None if row is None else self._stored(c, unit, row)

        return self._read(run)


def baseline_value_rows(bid: Any, baseline: Baseline) -> list[dict[str, Any]]:
    """``baseline_values`` rows of baseline version ``bid``."""
    return [{"baseline_id": bid, "parameter": p, "mean": m, "std": s, "n": int(c)}
            for p, m, s, c in zip(baseline.parameters, baseline.mean, baseline.std,
                                  baseline.count_array)]


def stored_baseline(unit: str, model: str | None, row: Any,
                    values: Sequence[tuple[Any, ...]]) -> StoredBaseline:
    """A baseline version from its ``baselines`` row and its ``(parameter,
    mean, std, n)`` values, parameters in ``model``'s order."""
    order = model_order(model, [v[0] for v in values])
    by = {v[0]: v for v in values}
    counts = tuple(int(row.n) if by[p][3] is None else int(by[p][3]) for p in order)
    base = Baseline(tuple(order), tuple(float(by[p][1]) for p in order),
                    tuple(float(by[p][2]) for p in order), int(row.n),
                    None if all(c == int(row.n) for c in counts) else counts)
    created = as_utc(row.created_at)
    assert created is not None
    return StoredBaseline(int(row.id), unit, str(row.name), int(row.version), created,
                          tuple(json.loads(row.test_ids)), base, row.reason,
                          tuple(json.loads(row.flags or "[]")))


# -- a unit's baseline in use, read from the store ------------------------------------
def members_of(latest: Sequence[Any] | None, usable: Sequence[tuple[Any, str]]) -> list[Any]:
    """Tests of a unit's active baseline: its latest version's tests
    (``latest``) still usable (``usable``: the unit's accepted, not excluded
    tests as ``(id, role)``, oldest first), or every usable healthy
    (``baseline``) test while no version exists (``latest`` None)."""
    if latest is None:
        return [i for i, role in usable if role == "baseline"]
    keep = {i for i, _ in usable}
    return [i for i in latest if i in keep]


def too_few_tests(unit: str, n: int, latest: Any) -> DataError:
    """The error of a unit whose baseline has ``n`` < 3 usable tests
    (``latest``: its latest version, with a ``name`` and ``version``, or None)."""
    why = ("" if latest is None else
           f" (baseline {latest.name!r} v{latest.version} after exclusions)")
    return DataError(f"unit {unit!r} has {n} accepted healthy test(s){why}; a "
                     f"baseline needs at least {MIN_BASELINE_TESTS}: add them with "
                     f"`condmon baseline add REC... --unit {unit}`")


def baseline_members(store: HistoryStore, unit: str) -> tuple[list[int], StoredBaseline | None]:
    """Tests of the unit's active baseline (its latest version without the
    tests excluded or rejected since), or every accepted, not excluded healthy
    test while no version exists; with that latest version."""
    if store.unit_model(unit) is None:  # a new unit: no tests yet
        return [], None
    latest = store.latest_baseline(unit)
    if latest is None:
        return store.usable_tests(unit, role="baseline"), None
    return members_of(latest.test_ids, [(i, "") for i in store.usable_tests(unit)]), latest


def _baseline_of(store: HistoryStore, unit: str, ids: Sequence[int]) -> Baseline:
    values, _ = store.estimates_of(ids)
    order = store.parameter_order(unit, list(values.columns))
    return make_baseline(values[order].to_numpy(), order)


def current_baseline(store: HistoryStore, unit: str) -> tuple[Baseline, list[int]]:
    """Baseline of a unit (its active baseline's tests) and their ids.

    Raises
    ------
    DataError
        Fewer than 3 usable tests.
    """
    ids, latest = baseline_members(store, unit)
    if len(ids) < MIN_BASELINE_TESTS:
        raise too_few_tests(unit, len(ids), latest)
    if latest is not None and list(latest.test_ids) == ids:
        return latest.baseline, ids
    return _baseline_of(store, unit, ids), ids
