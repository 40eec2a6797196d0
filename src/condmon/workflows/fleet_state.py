"""What a fleet batch knows of its units while it commits them, kept in memory.

A batch reads its units from the history once
(:meth:`~condmon.store.bulk.BulkMixin.unit_states`,
:meth:`~condmon.store.bulk.BulkMixin.record_rows`) and then decides every
record against this copy, which it keeps up to date with what it adds: the
tests, isolations and baseline versions of the batch are rows of a
:class:`~condmon.store.bulk.BulkWriter`, written together at the end, their
ids :class:`~condmon.store.bulk.Pending` until then. The answers are those of
the store's own reads (:func:`condmon.store.baselines.baseline_members`,
:func:`~condmon.store.baselines.current_baseline`, the duplicate checks of
:meth:`~condmon.store.history.TestsMixin.add_test`) had every record been
written on its own.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.monitor.baseline import MIN_BASELINE_TESTS, Baseline, assess_baseline, make_baseline
from condmon.monitor.conditions import explained
from condmon.store.base import model_order, num
from condmon.store.baselines import DEFAULT_BASELINE, members_of, too_few_tests
from condmon.store.bulk import BulkWriter, Id, KnownRow, Pending, UnitState, id_order

if TYPE_CHECKING:
    import pandas as pd

    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.workflows.records import RecordKey

__all__ = ["Version", "UnitView", "Known", "Records"]


def _no_flags() -> tuple[dict[str, Any], ...]:
    return ()


@dataclass(frozen=True)
class Version:
    """A version of a unit's active baseline (stored, or made in this batch).

    ``flags`` gives its plausibility flags once the batch is written (they
    name the tests' ids); a stored version's are not read again (empty).
    """

    id: Id
    name: str
    version: int
    test_ids: tuple[Id, ...]
    baseline: Baseline
    flags: Callable[[], tuple[dict[str, Any], ...]] = field(default=_no_flags, compare=False)


@dataclass(frozen=True)
class Known:
    """A test or isolation that may hold a record: stored, or added in this batch."""

    id: Id
    unit: str
    excluded: bool
    record_hash: str
    file_hash: str
    fingerprint: str | None


@dataclass
class UnitView:
    """A unit as the batch sees it: the history's copy and the batch's additions.

    Attributes
    ----------
    name : str
    uid : int or Pending or None
        None while the unit is not in the history.
    model : str or None
        Its model as the history names it (the declaration file, else the name).
    group : str or None
    label : str
        Its active baseline's name.
    latest : Version or None
    usable : list of (id, str)
        Its accepted, not excluded tests and their roles, oldest first.
    estimates : dict
        ``{test id: {parameter: (value, standard error)}}`` of its baseline's
        tests and of the tests added in the batch (NaN where the store has
        NULL). [parameter units]
    conditions : dict
        ``{test id: {condition: value}}`` of the same tests (those that have any).
    start_times : list of float
        The start times of its records, held and added, when its model
        declares the time since a session started as a condition (else
        empty). [s since the epoch]
    """

    name: str
    uid: Id | None = None
    model: str | None = None
    group: str | None = None
    label: str = DEFAULT_BASELINE
    latest: Version | None = None
    usable: list[tuple[Id, str]] = field(default_factory=list)
    estimates: dict[Id, dict[str, tuple[float, float]]] = field(default_factory=dict)
    conditions: dict[Id, dict[str, tuple[float, float]]] = field(default_factory=dict)
    start_times: list[float] = field(default_factory=list)

    @classmethod
    def of(cls, name: str, state: UnitState | None) -> UnitView:
        """The view of a unit from what the history holds of it (None: nothing)."""
        if state is None:
            return cls(name)
        latest = None if state.latest is None else Version(
            state.latest.id, state.latest.name, state.latest.version, state.latest.test_ids,
            state.latest.baseline)
        return cls(name, state.id, state.model_source or state.model, state.group_name,
                   state.baseline_name, latest, list(state.usable),
                   {i: dict(v) for i, v in state.estimates.items()},
                   {i: dict(v) for i, v in state.conditions.items()})

    # -- the unit's baseline ------------------------------------------------------------
    def members(self) -> list[Id]:
        """As :func:`condmon.store.baselines.baseline_members` (ids only)."""
        if self.uid is None:
            return []
        return members_of(None if self.latest is None else self.latest.test_ids, self.usable)

    def _matrix(self, ids: Sequence[Id], params: Sequence[str], column: int) -> np.ndarray:
        nan = (float("nan"), float("nan"))
        return np.array([[self.estimates.get(i, {}).get(p, nan)[column] for p in params]
                         for i in ids], dtype=np.float64).reshape(len(ids), len(params))

    def series(self, ids: Sequence[Id]) -> tuple[pd.DataFrame, pd.DataFrame]:
        """The tests' values and operating conditions (rows in the order of
        ``ids``), as :func:`~condmon.workflows.monitoring.conditioning` reads them."""
        import pandas as pd

        values = pd.DataFrame([{p: v for p, (v, _) in self.estimates.get(i, {}).items()}
                               for i in ids])
        return values, pd.DataFrame([{k: v for k, (v, _) in self.conditions.get(i, {}).items()}
                                     for i in ids])

    def errors(self, ids: Sequence[Id]) -> pd.DataFrame:
        """The tests' standard errors (rows in the order of ``ids``)."""
        import pandas as pd

        return pd.DataFrame([{p: se for p, (_, se) in self.estimates.get(i, {}).items()}
                             for i in ids])

    def parameters(self, ids: Sequence[Id]) -> list[str]:
        """The parameters the tests have, in the model's order."""
        names = sorted({p for i in ids for p in self.estimates.get(i, {})})
        return model_order(self.model, names)

    def baseline_of(self, ids: Sequence[Id]) -> Baseline:
        """As :func:`condmon.store.baselines._baseline_of`.

        Raises
        ------
        DataError
            No parameter with 3 tests.
        """
        order = self.parameters(ids)
        return make_baseline(self._matrix(ids, order, 0), order)

    def current(self) -> tuple[Baseline, list[Id]]:
        """As :func:`condmon.store.baselines.current_baseline`."""
        ids = self.members()
        if len(ids) < MIN_BASELINE_TESTS:
            raise too_few_tests(self.name, len(ids), self.latest)
        if self.latest is not None and list(self.latest.test_ids) == ids:
            return self.latest.baseline, ids
        return self.baseline_of(ids), ids

    def regime_counts(self, ids: Sequence[Id]) -> dict[str, int]:
        """Accepted healthy tests per regime among ``ids``."""
        from condmon.models.regimes import split_key

        counts: dict[str, int] = {}
        params = sorted({p for i in ids for p in self.estimates.get(i, {})})
        values = self._matrix(ids, params, 0)
        for j, key in enumerate(params):
            regime = split_key(key)[1]
            counts[regime] = max(counts.get(regime, 0), int(np.isfinite(values[:, j]).sum()))
        return counts

    def save_baseline(self, writer: BulkWriter, ids: Sequence[Id], *, reason: str,
                      monitor: MonitorConfig | None = None) -> Version:
        """As :func:`condmon.workflows.monitoring.save_current_baseline`: the
        next version of the active baseline from tests ``ids`` (the latest one
        when it has these tests already), its flags tested with ``ids`` in the
        order given: the order the records were run (by date when known)."""
        from condmon.models.registry import get_model
        from condmon.monitor.generic import machine_monitor

        base = self.baseline_of(ids)
        params = list(base.parameters)
        values, ses = self._matrix(ids, params, 0), self._matrix(ids, params, 1)
        cfg = monitor or machine_monitor(get_model(self.model or "dc-motor"), base)
        members = tuple(sorted(set(ids), key=id_order))
        last = self.latest
        if last is not None and list(last.test_ids) == list(members):
            return last
        assert self.uid is not None
        order = list(ids)
        version = 1 if last is None else last.version + 1
        # the flags name the tests: made once they are written and have their ids
        found: list[tuple[dict[str, Any], ...]] = []

        conds = self.series(order)[1]
        if len(conds.columns):   # a trend its operating conditions explain is no trend
            values = explained(values, params, {str(c): conds[c].to_numpy(dtype=np.float64)
                                                for c in conds.columns})

        def flags() -> tuple[dict[str, Any], ...]:
            if not found:
                found.append(assess_baseline(values, ses, [int(i) for i in order],
                                             base.parameters, cfg.baseline))
            return found[0]

        bid = writer.add_baseline(self.uid, base, members, name=self.label, version=version,
                                  reason=reason, flags=flags)
        self.latest = Version(bid, self.label, version, members, base, flags)
        return self.latest

    # -- adding ---------------------------------------------------------------------------
    def ensure(self, writer: BulkWriter, model: str, model_source: str | None) -> Id:
        """The unit's id, the unit added (with ``model``) when it is new."""
        if self.uid is None:
            self.uid = writer.add_unit(self.name, model, model_source)
            self.model = model_source or model
        return self.uid

    def added_test(self, tid: Pending, result: Any, role: str) -> None:
        """Keep a test just added: its estimates, and whether it is usable."""
        stored = (result.stored_values() if hasattr(result, "stored_values") else {})
        self.estimates[tid] = {p: (_stored(v), _stored(se)) for p, (v, se) in stored.items()}
        if getattr(result, "conditions", None):
            self.conditions[tid] = dict(result.conditions)
        if bool(getattr(result, "usable", result.accepted)):
            self.usable.append((tid, role))


def _stored(x: Any) -> float:
    """A value as the store gives it back (NULL, for a non-finite one, as NaN)."""
    v = num(x)
    return float("nan") if v is None else v


@dataclass
class Records:
    """The stored tests and isolations that may hold the batch's records, and
    the batch's own, to find a record's copies."""

    rows: dict[str, list[Known]] = field(default_factory=dict)  # kind -> rows, oldest first

    @classmethod
    def of(cls, known: dict[str, list[KnownRow]]) -> Records:
        return cls({kind: [Known(r.id, r.unit, r.excluded, r.record_hash, r.file_hash,
                                 r.fingerprint) for r in rows] for kind, rows in known.items()})

    def add(self, kind: str, rid: Pending, unit: str, key: RecordKey) -> None:
        self.rows.setdefault(kind, []).append(Known(rid, unit, False, key.content, key.file,
                                                    key.fingerprint))

    def copy_of(self, kind: str, unit: str, key: RecordKey) -> Known | None:
        """As :meth:`condmon.store.base.StoreBase._copy_of`: the unit's row of
        the same file or content, else of the same content by fingerprint."""
        from condmon.io.digest import same_content

        mine = [r for r in self.rows.get(kind, []) if r.unit == unit]
        for r in mine:
            if r.record_hash == key.content or r.file_hash == key.file:
                return r
        if not key.fingerprint:
            return None
        rows = int(json.loads(key.fingerprint)["n"])
        from condmon.io.digest import fingerprint_prefix

        start = fingerprint_prefix(rows)
        for r in mine:
            if r.fingerprint and r.fingerprint.startswith(start) and same_content(
                    key.fingerprint, r.fingerprint):
                return r
        return None

    def elsewhere(self, unit: str, key: RecordKey) -> Callable[[], str | None]:
        """As :func:`condmon.workflows.monitoring.filed_elsewhere`, once the ids are known."""
        others = [(r.unit, r.id) for r in self.rows.get("test", [])
                  if r.record_hash == key.content and r.unit != unit]

        def text() -> str | None:
            from condmon.workflows.monitoring import elsewhere_warning

            return elsewhere_warning([(u, int(i)) for u, i in others])

        return text
