"""Managing a history: exclude a wrong test, include it again, rebuild a baseline.

Nothing is deleted. An excluded test stays in the history, marked, with the
reason; a baseline change is a new version; every change is in the audit trail
(who, when, why). After the active baseline changes, the unit's checks are
evaluated against the new version (their earlier evaluations are kept), so the
trends, symptoms and reports follow the change, and an ``include`` restores
them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from condmon.errors import ConfigError, DataError
from condmon.monitor.baseline import MIN_BASELINE_TESTS
from condmon.store.baselines import StoredBaseline
from condmon.store.db import HistoryStore
from condmon.workflows.monitoring import baseline_members, reevaluate, save_current_baseline

__all__ = ["ChangeResult", "exclude_test", "include_test", "rebuild_baseline", "exclude_isolation",
           "include_isolation"]


@dataclass(frozen=True)
class ChangeResult:
    """What a history change did.

    Attributes
    ----------
    unit : str
    message : str
        One sentence for the user.
    baseline : StoredBaseline or None
        The unit's active baseline afterwards (None when too few tests remain).
    new_version : bool
        Whether the change made a new baseline version.
    reevaluated : dict of int to (str or None, str)
        Checks evaluated against the new baseline: ``{test_id: (status before, now)}``.
    """

    unit: str
    message: str
    baseline: StoredBaseline | None
    new_version: bool
    reevaluated: dict[int, tuple[str | None, str]] = field(default_factory=dict)

    @property
    def changed_status(self) -> dict[int, tuple[str | None, str]]:
        """The re-evaluated checks whose status changed."""
        return {k: v for k, v in self.reevaluated.items() if v[0] != v[1]}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"unit": self.unit, "message": self.message,
                "baseline": None if self.baseline is None else self.baseline.to_dict(),
                "new_version": self.new_version,
                "reevaluated": {str(k): {"before": b, "now": a}
                                for k, (b, a) in self.reevaluated.items()}}


def _reason(reason: str | None, what: str) -> str:
    text = (reason or "").strip()
    if not text:
        raise ConfigError(f"{what} needs a reason (--reason TEXT): it is kept in the audit trail")
    return text


def _not_yet(info: Mapping[str, Any], what: str, *, excluded: bool) -> Mapping[str, Any]:
    """``info`` when its record can be excluded (``excluded``) or included."""
    if excluded and info["excluded"]:
        raise DataError(f"{what} of {info['unit']!r} is already excluded "
                        f"({info['excluded_reason']})")
    if not excluded and not info["excluded"]:
        raise DataError(f"{what} of {info['unit']!r} is not excluded")
    return info


def _apply(store: HistoryStore, unit: str, ids: Sequence[int], reason: str,
           name: str | None = None) -> ChangeResult:
    """Make ``ids`` the next version of the unit's baseline (or ``name``) and
    evaluate the checks against it."""
    ids = sorted(set(int(i) for i in ids))
    if len(ids) < MIN_BASELINE_TESTS:
        return ChangeResult(unit, f"the baseline of {unit!r} would keep {len(ids)} test(s); "
                            f"checks need at least {MIN_BASELINE_TESTS} (add healthy tests "
                            "or include one again)", None, False)
    stored, fresh = save_current_baseline(store, unit, ids, name=name, reason=reason)
    changed = reevaluate(store, unit, stored)
    what = (f"baseline {stored.name!r} v{stored.version} from {stored.baseline.n} tests"
            if fresh else f"baseline {stored.name!r} v{stored.version} unchanged")
    return ChangeResult(unit, what, stored, fresh, changed)


def exclude_test(store: HistoryStore, test_id: int, reason: str | None) -> ChangeResult:
    """Exclude a test from its unit's baseline, trends and reports (kept, marked).

    A baseline test leaves the active baseline (a new version); the unit's
    checks are then evaluated against it.

    Raises
    ------
    ConfigError
        No such test, or no reason given.
    DataError
        The test is already excluded.
    """
    why = _reason(reason, "exclude")
    info = _not_yet(store.test_info(test_id), f"test #{test_id}", excluded=True)
    unit = str(info["unit"])
    store.set_excluded(test_id, True, why)
    ids, latest = baseline_members(store, unit)
    if latest is None or int(test_id) not in latest.test_ids:
        return ChangeResult(unit, f"test #{test_id} excluded; the baseline is unchanged",
                            latest, False)
    res = _apply(store, unit, ids, f"test #{test_id} excluded: {why}")
    return ChangeResult(unit, f"test #{test_id} excluded; {res.message}", res.baseline,
                        res.new_version, res.reevaluated)


def include_test(store: HistoryStore, test_id: int, reason: str | None = None) -> ChangeResult:
    """Include an excluded test again; a test that was in the active baseline
    before its exclusion goes back into it (a new version).

    Raises
    ------
    ConfigError
        No such test.
    DataError
        The test is not excluded.
    """
    info = _not_yet(store.test_info(test_id), f"test #{test_id}", excluded=False)
    unit = str(info["unit"])
    why = (reason or "").strip() or "included again"
    store.set_excluded(test_id, False, why)
    ids, latest = baseline_members(store, unit)
    active = store.active_baseline_name(unit)
    was_member = any(int(test_id) in b.test_ids for b in store.baselines(unit)
                     if b.name == active)
    if not was_member or not info["accepted"]:
        changed = ({} if latest is None or list(latest.test_ids) != ids
                   else reevaluate(store, unit, latest))  # an included check is evaluated
        return ChangeResult(unit, f"test #{test_id} included; the baseline is unchanged",
                            latest, False, changed)
    res = _apply(store, unit, [*ids, int(test_id)], f"test #{test_id} included: {why}")
    return ChangeResult(unit, f"test #{test_id} included; {res.message}", res.baseline,
                        res.new_version, res.reevaluated)


def exclude_isolation(store: HistoryStore, isolation_id: int, reason: str | None
                      ) -> ChangeResult:
    """Exclude an isolation (a wrong record, the wrong unit) from the unit's
    status, trends and reports; it is kept, marked and audited.

    Raises
    ------
    ConfigError
        No such isolation, or no reason given.
    DataError
        The isolation is already excluded.
    """
    why = _reason(reason, "exclude")
    info = _not_yet(store.isolation_info(isolation_id), f"isolation i{isolation_id}",
                    excluded=True)
    store.set_isolation_excluded(isolation_id, True, why)
    unit = str(info["unit"])
    return ChangeResult(unit, f"isolation i{isolation_id} excluded",
                        store.latest_baseline(unit), False)


def include_isolation(store: HistoryStore, isolation_id: int, reason: str | None = None
                      ) -> ChangeResult:
    """Include an excluded isolation again.

    Raises
    ------
    ConfigError
        No such isolation.
    DataError
        The isolation is not excluded.
    """
    info = _not_yet(store.isolation_info(isolation_id), f"isolation i{isolation_id}",
                    excluded=False)
    store.set_isolation_excluded(isolation_id, False, (reason or "").strip() or "included again")
    unit = str(info["unit"])
    return ChangeResult(unit, f"isolation i{isolation_id} included",
                        store.latest_baseline(unit), False)


def rebuild_baseline(store: HistoryStore, unit: str, *, reason: str | None,
                     name: str | None = None, test_ids: Sequence[int] | None = None
                     ) -> ChangeResult:
    """A new baseline version from chosen tests (default: every accepted, not
    excluded healthy test of the unit), made the unit's active baseline under
    ``name`` (default: the active one's name); checks are evaluated against it.

    Raises
    ------
    ConfigError
        No reason, or an unknown unit.
    DataError
        A chosen test is not the unit's, rejected, excluded or a check judged
        no-go or advisory, or fewer than 3.
    """
    why = _reason(reason, "baseline rebuild")
    store.unit_id(unit)  # the error names the known units
    hist = store.history(unit)
    if test_ids is None:
        usable = hist[(hist["role"] == "baseline") & hist["accepted"] & ~hist["excluded"]]
        ids = [int(i) for i in usable.index]
    else:
        ids = sorted(set(int(i) for i in test_ids))
        bad = [f"#{i} ({_why_unusable(hist, i, unit)})" for i in ids
               if _why_unusable(hist, i, unit)]
        if bad:
            raise DataError(f"cannot build a baseline of {unit!r} from {', '.join(bad)}")
    if len(ids) < MIN_BASELINE_TESTS:
        raise DataError(f"a baseline needs at least {MIN_BASELINE_TESTS} accepted tests; "
                        f"{len(ids)} chosen for {unit!r}")
    res = _apply(store, unit, ids, why, name=name)
    return res


def _why_unusable(hist: Any, test_id: int, unit: str) -> str:
    if test_id not in hist.index:
        return f"not a test of {unit!r}"
    row = hist.loc[test_id]
    if row["excluded"]:
        return "excluded"
    if not row["accepted"]:
        return "rejected"
    status = row.get("status")
    if row["role"] == "check" and status in ("no-go", "advisory"):
        # a baseline of changed tests would hide the very change it is there to show
        return f"a check judged {status}; a baseline is made of healthy tests"
    return ""


def set_unit_model(store: HistoryStore, unit: str, model: str, reason: str | None = None
                   ) -> ChangeResult:
    """Point ``unit`` at the declaration file ``model`` (moved, renamed, or a
    new version of the unit's machine), kept with the unit and audited.

    The file must be a valid declaration of the kind the unit is monitored
    with (one that estimates, or one that isolates); it must report every
    parameter the unit's tests have stored. The message says whether it
    means the same as the unit's kept declaration.

    Raises
    ------
    ConfigError
        The file is not a valid declaration, or it lacks a stored parameter.
    """
    from pathlib import Path

    from condmon.models.registry import get_model
    from condmon.models.regimes import split_key
    from condmon.store.declarations import bundle_digest

    if Path(model).suffix.lower() != ".toml":
        raise ConfigError(f"{model}: a unit is re-pointed to a declaration file (.toml); a "
                          "shipped model is given by name at the unit's first record")
    machine = get_model(model)
    store.unit_id(unit)   # an unknown unit: the close names
    hist = store.history(unit)
    stored = {split_key(str(c))[0] for c in hist.columns if f"{c}_se" in hist.columns}
    missing = sorted(stored - set(machine.monitored))
    if missing:
        raise ConfigError(f"{model}: does not report {', '.join(missing)}, which the history "
                          f"of {unit!r} holds; not re-pointed")
    assert machine.origin is not None
    _, before = store.unit_declaration(unit)
    same = before is not None and bundle_digest(machine.origin) == before
    what = ("the same declaration at a new path" if same else
            "a declaration that differs from the one the unit's tests were judged with")
    store.set_unit_model(unit, machine.origin, name=machine.name, reason=reason or what)
    return ChangeResult(unit, f"{unit} now uses {machine.origin} ({machine.name}): {what}",
                        store.latest_baseline(unit), False)
