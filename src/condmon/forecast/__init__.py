"""Forecasting: when a unit's trended parameters turn no-go, with calibrated intervals.

``series`` forecasts one change series (two degradation models averaged by
their evidence, the fleet's prior); ``degradation`` fits them; ``prior``
learns from a fleet's degraded units; ``path`` forecasts a measured
degradation path (a wandering rate, recoveries), ``measured`` makes it a
forecast like the others and states each method's measured coverage, and
``calibration`` reads it at the levels the fleet's failed units call for,
``similar`` sets their remaining lives beside it (stacked);
``axis`` puts a unit's checks on one axis (tests, days, operating hours or
cycles); ``unit`` forecasts every parameter of a unit to its no-go change. The stage reads baselines from :mod:`condmon.monitor` and
is read by diagnosis, the store and the reports.
"""

from condmon.forecast.series import Forecast, forecast_series

__all__ = ["Forecast", "forecast_series"]
