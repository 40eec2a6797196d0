"""condmon — model-based condition monitoring of machines.

From a short test record, estimate the physical parameters of a machine
(refined instrumental-variable identification, exact zero-order-hold inverse),
check the fit, and report each parameter with its standard error.

Monitoring a unit over time goes through :class:`History` (a SQLite file or
a PostgreSQL URL): ``baseline_add``, ``check``, ``import_table`` (measured
indicators), ``history``, ``forecast``, ``units``; plant models with
residuals through :func:`isolate`.

Example
-------
>>> import condmon
>>> rec = condmon.simulate_actuator(seed=1)
>>> res = condmon.estimate(rec)
>>> round(res.parameters["R"], 2)
1.0
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from condmon._lazy import load, names
from condmon.errors import (
    CondmonError, CondmonWarning, ConfigError, ConversionError, ConvergenceWarning,
    DataError, DataWarning, EstimationError, ModelError,
)

if TYPE_CHECKING:
    from condmon.identify import EstimateResult, estimate
    from condmon.io import read_record
    from condmon.simulate import load_actuator_rig, simulate_actuator
    from condmon.workflows.api import Forecast, History, isolate, load_model, validate
    from condmon.workflows.checks import CheckResult

__version__ = "0.1.0"

__all__ = [
    "estimate", "EstimateResult", "read_record", "simulate_actuator", "load_actuator_rig",
    "History", "CheckResult", "Forecast", "isolate", "load_model", "validate",
    "CondmonError", "DataError", "ConfigError", "ModelError", "ConversionError",
    "EstimationError", "CondmonWarning", "DataWarning", "ConvergenceWarning",
    "__version__",
]

# Imported on first use (PEP 562): ``import condmon`` stays cheap.
_EXPORTS = {"estimate": "condmon.identify", "EstimateResult": "condmon.identify",
            "read_record": "condmon.io", "simulate_actuator": "condmon.simulate",
            "load_actuator_rig": "condmon.simulate", "History": "condmon.workflows.api",
            "Forecast": "condmon.workflows.api", "isolate": "condmon.workflows.api",
            "load_model": "condmon.workflows.api", "validate": "condmon.workflows.api",
            "CheckResult": "condmon.workflows.checks"}


def __getattr__(name: str) -> Any:
    return load(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return names(globals(), _EXPORTS)
