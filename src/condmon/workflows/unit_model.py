"""A unit's model when a record is offered for it: the stored one filled in,
the same declaration at a new path re-pointed, another refused; and what the
unit's history adds to a record's conditions (the time since its session
started)."""

from __future__ import annotations

import dataclasses

from condmon.errors import DataError
from condmon.identify.result import EstimateResult
from condmon.monitor.conditions import with_session_time
from condmon.workflows.records import EstimateOptions, RecordKey
from condmon.models.machine import Machine
from condmon.models.registry import get_model
from condmon.store.db import HistoryStore

__all__ = ["unit_options", "repoint", "session_timed"]


def unit_options(store: HistoryStore, unit: str, opts: EstimateOptions) -> EstimateOptions:
    """Options with the unit's model filled in; refuses a record offered with
    another model than the one the unit's history was started with."""
    stored = store.unit_model(unit)
    if stored is not None and get_model(stored).indicators is not None:
        get_model(stored).require_estimation()   # says: imported, not estimated
    if stored is not None and not get_model(stored).spec.unknowns:
        raise DataError(f"unit {unit!r} is monitored with plant model {stored!r}: its records "
                        f"are isolated (`condmon isolate {stored} REC --unit {unit}`), not "
                        "estimated")
    if opts.model is None:
        return dataclasses.replace(opts, model=stored or "dc-motor")
    if stored is not None:
        machine = get_model(opts.model)
        if stored not in (machine.name, machine.origin):
            repoint(store, unit, machine, stored)
    return opts


def repoint(store: HistoryStore, unit: str, machine: Machine, stored: str) -> None:
    """Accept a record offered with another path of the unit's declaration:
    the same equations, parameters and rules (the digest of their meaning,
    :mod:`condmon.models.bundle`) at a new path re-point the unit to it
    (audited); another declaration is refused, naming both and how to
    re-point on purpose."""
    from condmon.store.declarations import bundle_digest

    _, kept = store.unit_declaration(unit)
    new = bundle_digest(machine.origin) if machine.origin else None
    if kept is not None and new == kept:
        assert machine.origin is not None
        store.set_unit_model(unit, machine.origin, name=machine.name,
                             reason="the same declaration at a new path")
        return
    what = ("its equations, parameters or rules differ from the unit's"
            if kept is not None and new is not None else "another model")
    raise DataError(f"unit {unit!r} is monitored with model {stored!r}; this record was "
                    f"offered with {machine.origin or machine.name!r}, {what} (omit --model "
                    f"to use the unit's; `condmon unit set-model {unit} FILE` re-points the "
                    "unit on purpose)")


def session_timed(store: HistoryStore, unit: str, res: EstimateResult, machine: Machine,
                  key: RecordKey) -> EstimateResult:
    """``res`` with the time since its session started, for a machine that
    declares it as a condition (:func:`~condmon.monitor.conditions.with_session_time`,
    from the start times of the unit's records the history holds)."""
    if not machine.sessions:
        return res
    return with_session_time(res, machine.sessions, key.test_date, store.start_times(unit))

