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

from condmon.forecast.unit import ParameterForecast, UnitForecast
from condmon.store.db import HistoryStore
from condmon.store.forecasts import read_forecast

__all__ = ["ParameterForecast", "UnitForecast", "forecast_unit"]


def forecast_unit(store: HistoryStore, unit: str, horizon: float | None = None,
                  seed: int = 0) -> UnitForecast:
    """Forecast every parameter of ``unit`` to no-go (:func:`~condmon.store.forecasts.read_forecast`).

    Raises
    ------
    DataError
        Fewer than 3 checks since the baseline ("not enough tests to
        forecast"), a horizon <= 0.
    """
    return read_forecast(store, unit, horizon, seed)
