"""A unit's forecasts to no-go, read from the history (the store-level reader).

:func:`read_forecast` gathers what :func:`condmon.monitor.unit_forecast.
forecast_checks` needs from the store (the current baseline, the checks since
it, the model's breakpoints and fault rules) and forecasts; ``condmon
forecast``, ``condmon check``, the report and the fleet page all forecast
through it. :func:`fleet_summaries` is every unit's listing (``condmon units
--json`` and the page's ``/api/units``) with each unit's earliest forecast;
:func:`by_urgency` orders it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError
from condmon.monitor.baseline import MIN_BASELINE_TESTS
from condmon.monitor.unit_forecast import NO_TREND, UnitForecast, forecast_checks
from condmon.store.baselines import baseline_members, current_baseline

if TYPE_CHECKING:
    from condmon.store.db import HistoryStore

__all__ = ["read_forecast", "try_forecast", "forecast_fields", "fleet_summaries",
           "by_urgency", "NO_BASELINE"]

#: Why a unit without a baseline in use has no forecast.
NO_BASELINE = "no baseline yet"


def read_forecast(store: HistoryStore, unit: str, horizon: float | None = None,
                  seed: int = 0) -> UnitForecast:
    """Forecast every parameter of ``unit`` to no-go, from its checks since its
    current baseline (accepted, not excluded), against its model's ``r2``.

    Parameters
    ----------
    store : HistoryStore
    unit : str
    horizon : float, optional
        For the probability of crossing within it. [tests (or d)]
    seed : int
        Seed of the predictive draws.

    Raises
    ------
    DataError
        No baseline, fewer than 3 checks since it ("not enough tests to
        forecast"), a horizon <= 0.
    ConfigError
        An unknown unit (the message names the close ones).
    """
    from condmon.diagnose.rules import machine_rules
    from condmon.models.registry import get_model
    from condmon.monitor.generic import machine_monitor

    store.unit_id(unit)  # an unknown unit: the close names
    baseline, ids = current_baseline(store, unit)
    machine = get_model(store.unit_model(unit) or "dc-motor")
    hist = store.history(unit)
    checks = hist[(hist["role"] == "check") & hist["accepted"].astype(bool)
                  & ~hist["excluded"].astype(bool)]
    checks = checks[[i not in ids for i in checks.index]]
    rules: dict[str, str] = {}
    for r in machine_rules(machine).faults:  # the first rule of each one-symptom condition
        rules.setdefault(r.text.strip(), r.name)
    return forecast_checks(unit, checks, baseline, machine_monitor(machine, baseline).r2,
                           rules, machine.units, horizon, seed)


def try_forecast(store: HistoryStore, unit: str) -> tuple[UnitForecast | None, str | None]:
    """:func:`read_forecast`, or why there is none: ``(forecast, None)`` or
    ``(None, reason)`` (no baseline yet, too few usable healthy tests for
    one, not enough tests to forecast, the model cannot be loaded); never raises a :class:`~condmon.errors.CondmonError`."""
    usable = 0 if store.unit_model(unit) is None else len(baseline_members(store, unit)[0])
    if usable < MIN_BASELINE_TESTS:
        return None, NO_BASELINE if not usable else (
            f"no baseline: {usable} usable healthy test(s), a baseline needs "
            f"{MIN_BASELINE_TESTS}")
    try:
        return read_forecast(store, unit), None
    except CondmonError as err:
        return None, str(err)


def forecast_fields(res: UnitForecast | None, reason: str | None) -> dict[str, Any]:
    """``{"forecast", "forecast_reason"}`` of a unit's listing (and of ``check --json``).

    ``forecast`` is the earliest forecast to no-go
    (:meth:`~condmon.monitor.unit_forecast.UnitForecast.summary`:
    ``parameter, unit, by, median, low, high, date, rule``) or None;
    ``forecast_reason`` says why it is None (``no baseline yet``, ``not
    enough tests to forecast: ...``, ``no trend towards no-go``), else None.
    """
    summary = None if res is None else res.summary()
    why = reason if res is None else (NO_TREND if summary is None else None)
    return {"forecast": summary, "forecast_reason": why}


def fleet_summaries(store: HistoryStore) -> list[dict[str, Any]]:
    """:meth:`HistoryStore.unit_summaries`, each unit with its earliest forecast
    to no-go (:func:`forecast_fields`): what ``condmon units --json`` and the
    fleet page's ``/api/units`` list."""
    rows = store.unit_summaries()
    for r in rows:
        r.update(forecast_fields(*try_forecast(store, str(r["unit"]))))
    return rows


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
    """Units (rows of :func:`fleet_summaries`) by their earliest forecast to no-go.

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
