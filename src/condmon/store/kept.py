"""Forecasts kept in the history: for the fleet's listings, and the wear the next checks learn from.

:func:`fleet_summaries` is every unit's listing (``condmon units --json`` and
the page's ``/api/units``) with each unit's earliest forecast, reused while
its history and its count of degraded peers are unchanged
(:func:`~condmon.store.views.by_urgency` orders it). :func:`keep_forecast`
keeps a unit's forecast after a check; :func:`keep_fitted` keeps the wear of
peers fitted from their histories. :data:`FORECAST_METHOD` says what a kept
forecast means: a history kept by an older method is renewed.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError
from condmon.store.forecasts import FleetHistory, forecast_fields, try_forecast

if TYPE_CHECKING:
    from condmon.store.db import HistoryStore

__all__ = ["fleet_summaries", "attach_forecasts", "keep_forecast", "keep_fitted",
           "current_method", "FORECAST_METHOD", "PEER_RATES_ONLY"]

#: Forecasts this process made, by (history, unit): (its latest change, its
#: degraded peers, the fields); for listings of a history it cannot write.
_MADE: dict[tuple[str, str], tuple[int, int, dict[str, Any]]] = {}
_MADE_MAX = 100_000


def fleet_summaries(store: HistoryStore) -> list[dict[str, Any]]:
    """:meth:`HistoryStore.unit_summaries`, each unit with its earliest forecast
    to no-go (:func:`forecast_fields`): what ``condmon units --json`` and the
    fleet page's ``/api/units`` list.

    A unit's forecast is the one kept when its history and its count of
    degraded peers are unchanged since (:func:`keep_forecast` after each
    check), or the one this process made last for the same history (the
    fleet page reads a history it may not write); the others are forecast
    and kept (when the history can be written), so a listing forecasts only
    what changed.
    """
    return attach_forecasts(store, store.unit_summaries())


def attach_forecasts(store: HistoryStore, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each of ``rows`` (entries of :meth:`HistoryStore.unit_summaries`) with
    its unit's earliest forecast to no-go (:func:`forecast_fields`), in place;
    kept forecasts reused as :func:`fleet_summaries` says. Returns ``rows``."""
    if not rows:
        return rows
    names = [str(r["unit"]) for r in rows]
    marks = store.history_marks(names)
    kept = store.kept_forecasts(names) if current_method(store) else {}
    fleet = FleetHistory(store)
    fleet.know(names)
    models = {u: (m, g) for u, m, g in store.unit_models(names)}
    fresh = []
    for r in rows:
        unit = str(r["unit"])
        model, group = models.get(unit, (None, None))
        peers = fleet.peer_count(unit, model, group)
        mark, old = marks.get(unit, 0), kept.get(unit)
        if old is not None and old[:2] == (mark, peers):
            r.update({"forecast": None if old[2] is None else json.loads(old[2]),
                      "forecast_reason": old[3]})
            continue
        made = _MADE.get((store.url, unit))
        if made is not None and made[:2] == (mark, peers):
            r.update(made[2])
            continue
        fields = forecast_fields(*try_forecast(store, unit, fleet, r))
        r.update(fields)
        if len(_MADE) >= _MADE_MAX:
            _MADE.clear()
        _MADE[(store.url, unit)] = (mark, peers, fields)
        fresh.append(_kept_row(unit, mark, peers, fields, fleet))
    try:
        store.keep_forecasts(fresh)
    except CondmonError:   # a history opened read-only, or busy: forecast again next time
        pass
    return rows


#: The peer count of a kept row that holds only a unit's wear for its peers'
#: priors, no forecast of its own: matches no unit's count, so a listing
#: forecasts that unit afresh (and replaces the row) while the wear is reused.
PEER_RATES_ONLY = -1


def _kept_row(unit: str, mark: int, peers: int, fields: dict[str, Any], fleet: FleetHistory
              ) -> tuple[Any, ...]:
    return (unit, mark, peers, fields["forecast"], fields["forecast_reason"],
            fleet.rates_of(unit))


#: What a kept forecast means: raised when forecasts change their meaning
#: (2: to the change at which a check turns no-go, the fleet's priors by
#: direction; 3: mid-p intervals, the scale read from the residuals, the way
#: of a steady move; 4: faults of two symptoms; 5: a trend needs the unit's
#: own checks to move, not its peers' prior alone; 6: a path forecast is
#: recalibrated only on three failed peers or more; 7: its chance within a
#: horizon read on the fleet too), so the forecasts and wear kept by an
#: older method are made again.
FORECAST_METHOD = 7

_CURRENT: set[str] = set()   # histories whose kept forecasts are the current method's


def current_method(store: HistoryStore) -> bool:
    """Whether ``store``'s kept forecasts are the current method's
    (:data:`FORECAST_METHOD`): if not, they are dropped and the method
    recorded (a history that cannot be written: False, so none is reused)."""
    if store.url in _CURRENT:
        return True
    if store.forecast_method() != FORECAST_METHOD:
        try:
            store.renew_forecasts(FORECAST_METHOD)
        except CondmonError:   # read-only or busy: forecast afresh, keep nothing
            return False
    _CURRENT.add(store.url)
    return True


def keep_forecast(store: HistoryStore, unit: str, fit_peers: bool = False) -> dict[str, Any]:
    """Forecast ``unit`` (:func:`try_forecast`), keep it for the fleet
    listings, and return its :func:`forecast_fields` (after a stored check).

    A check does not fit its peers' wear (``fit_peers=False``): peers whose
    wear is not kept are left out, said in the prior's notes, and the unit's
    forecast is kept as its wear only, so that the next listing forecasts it
    with them (:class:`FleetHistory`). With ``fit_peers``, the peers fitted
    keep their wear, so the next check reads it back."""
    current_method(store)
    fleet = FleetHistory(store, fit_peers=fit_peers)
    fields = forecast_fields(*try_forecast(store, unit, fleet))
    keep_fitted(store, fleet, unit, fields)
    return fields


def keep_fitted(store: HistoryStore, fleet: FleetHistory, unit: str,
                fields: dict[str, Any] | None = None) -> None:
    """Keep the wear of the peers ``fleet`` fitted from their histories (a
    method change, a copied history), so that later checks read it back, and
    ``unit``'s forecast ``fields`` (None: leave its kept row as it is): as
    its wear only when peers were left out of it (``fleet.unfitted``), so
    that the next listing forecasts it with them."""
    peers = [p for p in fleet.fitted() if p != unit]
    marks = store.history_marks([unit, *peers])
    rows = [(p, marks.get(p, 0), PEER_RATES_ONLY, None, None, fleet.rates_of(p)) for p in peers]
    if fields is not None and fleet.unfitted:
        rows.append((unit, marks.get(unit, 0), PEER_RATES_ONLY, None, None, fleet.rates_of(unit)))
    elif fields is not None:
        rows.append(_kept_row(unit, marks.get(unit, 0), fleet.peer_count(unit), fields, fleet))
    store.keep_forecasts(rows)
