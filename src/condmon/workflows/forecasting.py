"""``condmon forecast``: each parameter's forecast to no-go, from a unit's history.

For every parameter (and operating regime) of the unit, the checks since its
current baseline form the change series; :func:`condmon.monitor.forecast.
forecast_series` fits it and forecasts the crossing of the parameter's ``r2``
(in the trend's direction), naming the fault rule that single-parameter
change fires. The tests are counted, or their dates used (days) when every
check carries one.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from condmon.errors import DataError
from condmon.models.registry import get_model
from condmon.monitor.forecast import MIN_TESTS, Forecast, forecast_series
from condmon.store.db import HistoryStore
from condmon.workflows.monitoring import current_baseline, monitoring_of

__all__ = ["ParameterForecast", "UnitForecast", "forecast_unit"]


@dataclass(frozen=True)
class ParameterForecast:
    """One parameter's forecast.

    Attributes
    ----------
    parameter : str
        With its regime (``Tc@forward``) when the baseline has regimes.
    unit : str
        The parameter's unit of measure.
    rule : str
        The fault rule the threshold comes from ("" when none names it alone).
    forecast : Forecast
    date : str or None
        The median crossing date, ISO 8601 (when the checks carry dates).
    """

    parameter: str
    unit: str
    rule: str
    forecast: Forecast
    date: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "unit": self.unit, "rule": self.rule,
                "date": self.date, **self.forecast.to_dict()}


@dataclass(frozen=True)
class UnitForecast:
    """Every parameter's forecast for one unit.

    Attributes
    ----------
    unit : str
    by : {"tests", "days"}
        What ``remaining`` counts.
    checks : int
        Checks since the baseline.
    parameters : tuple of ParameterForecast
        Earliest median crossing first; "no trend" last.
    """

    unit: str
    by: str
    checks: int
    parameters: tuple[ParameterForecast, ...]

    @property
    def earliest(self) -> ParameterForecast | None:
        """The parameter forecast to turn no-go first (None: no trend anywhere)."""
        trends = [p for p in self.parameters if p.forecast.remaining is not None]
        return trends[0] if trends else None

    def to_dict(self) -> dict[str, Any]:
        e = self.earliest
        return {"unit": self.unit, "by": self.by, "checks": self.checks,
                "earliest": None if e is None else e.parameter,
                "parameters": [p.to_dict() for p in self.parameters]}


def _rule_for(rules: Any, parameter: str, direction: str) -> str:
    """The fault rule whose condition is this one symptom alone."""
    atom = re.compile(rf"^\s*{direction}\({re.escape(parameter)}\)\s*$")
    return next((r.name for r in rules.faults if atom.match(r.text)), "")


def forecast_unit(store: HistoryStore, unit: str, horizon: float | None = None,
                  seed: int = 0) -> UnitForecast:
    """Forecast every parameter of ``unit`` to no-go.

    Raises
    ------
    DataError
        Fewer than 3 checks since the baseline ("not enough tests to
        forecast"), a horizon <= 0.
    """
    if horizon is not None and not horizon > 0:
        raise DataError(f"horizon must be > 0, not {horizon:g}")
    store.unit_id(unit)  # an unknown unit: the close names
    baseline, ids = current_baseline(store, unit)
    machine = get_model(store.unit_model(unit) or "dc-motor")
    cfg, rules = monitoring_of(machine, baseline)
    hist = store.history(unit)
    checks = hist[(hist["role"] == "check") & hist["accepted"].astype(bool)
                  & ~hist["excluded"].astype(bool)]
    checks = checks[[i not in ids for i in checks.index]]
    if len(checks) < MIN_TESTS:
        raise DataError(f"not enough tests to forecast: unit {unit!r} has {len(checks)} "
                        f"check(s) since its baseline, need {MIN_TESTS}")
    dates = pd.to_datetime(checks["test_date"], utc=True, errors="coerce")
    by = "days" if dates.notna().all() and dates.is_monotonic_increasing \
        and dates.nunique() == len(dates) else "tests"
    units = machine.units
    out = []
    for key, mean, std in zip(baseline.parameters, baseline.mean, baseline.std):
        name = key.split("@", 1)[0]
        col = f"{key}_change"   # a regime's parameter has columns of its own (Tc@forward)
        if col not in checks or name not in cfg.r2:
            continue
        rows = checks[checks[col].notna()]
        if len(rows) < MIN_TESTS:
            continue
        x = (np.arange(1.0, len(rows) + 1.0) if by == "tests" else
             ((dates[rows.index] - dates.iloc[0]).dt.total_seconds() / 86400.0).to_numpy())
        change = rows[col].to_numpy(dtype=np.float64)
        se = 100.0 * rows[f"{key}_se"].to_numpy(dtype=np.float64) / abs(mean) \
            if f"{key}_se" in rows and mean else np.zeros(len(rows))
        rising = float(np.nanmean(change[-MIN_TESTS:])) >= 0.0
        threshold = cfg.r2[name] if rising else -cfg.r2[name]
        rule = _rule_for(rules, name, "high" if rising else "low")
        f = forecast_series(x, change, np.nan_to_num(se), 100.0 * std / abs(mean) if mean else 0.0,
                            threshold, horizon, seed)
        when = None
        if by == "days" and f.remaining is not None and np.isfinite(f.remaining[0]):
            when = (dates.iloc[-1] + pd.Timedelta(days=f.remaining[0])).isoformat()
        out.append(ParameterForecast(key, units.get(name, ""), rule, f, when))
    out.sort(key=lambda p: (p.forecast.remaining is None,
                            p.forecast.remaining[0] if p.forecast.remaining else 0.0))
    return UnitForecast(unit, by, len(checks), tuple(out))
