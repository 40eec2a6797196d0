"""Forecasting: when a unit's trended parameters turn no-go, with calibrated intervals.

``series`` forecasts one change series (two degradation models averaged by
their evidence, the fleet's prior); ``degradation`` fits them; ``prior``
learns from a fleet's degraded units; ``axis`` puts a unit's checks on one
axis (tests, days or operating hours); ``unit`` forecasts every parameter of
a unit to its no-go change; ``wiener`` is the first passage of a Wiener
degradation path. The stage reads baselines from :mod:`condmon.monitor` and
is read by diagnosis, the store and the reports.
"""

from condmon.forecast.series import Forecast, forecast_series

__all__ = ["Forecast", "forecast_series"]
