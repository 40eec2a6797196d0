"""``condmon forecast``: each parameter's forecast to no-go, from a unit's history.

For every parameter (and operating regime) of the unit, the checks since its
current baseline form the change series; :func:`condmon.forecast.series.
forecast_series` fits it and forecasts the crossing of the parameter's ``r2``
(in the trend's direction), naming the fault rule that single-parameter
change fires. The tests are counted, or their dates used (days) when every
check carries one.

The work is done below the report stage, so the report and the fleet page
forecast alike: :func:`condmon.forecast.unit.forecast_checks` (pure)
and :func:`condmon.store.forecasts.read_forecast` (reads the store); this
module keeps the workflow's names.
"""

from __future__ import annotations

from condmon.errors import CondmonError
from condmon.forecast.unit import ParameterForecast, UnitForecast
from condmon.store.db import HistoryStore
from condmon.store.forecasts import FleetHistory, read_forecast
from condmon.store.kept import current_method, keep_fitted

__all__ = ["ParameterForecast", "UnitForecast", "forecast_unit"]


def forecast_unit(store: HistoryStore, unit: str, horizon: float | None = None,
                  seed: int = 0) -> UnitForecast:
    """Forecast every parameter of ``unit`` to no-go (:func:`~condmon.store.forecasts.read_forecast`).

    The wear of degraded peers that had to be fitted from their histories
    (none kept, or kept by an older method) is kept, with the unit's own, so
    that the next check of any of them reads it back.

    Raises
    ------
    DataError
        Fewer than 3 checks since the baseline ("not enough tests to
        forecast"), a horizon <= 0.
    """
    fleet = FleetHistory(store)
    out = read_forecast(store, unit, horizon, seed, fleet)
    if fleet.fitted():   # peers' wear fitted here is kept: later checks read it back
        try:
            if current_method(store):
                keep_fitted(store, fleet, unit)
        except CondmonError:   # a history opened read-only, or busy: fitted again next time
            pass
    return out
