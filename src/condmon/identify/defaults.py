"""Names and defaults of the estimation pipeline, importable without numpy (the
command line's help texts show them before any estimator is imported)."""

from __future__ import annotations

__all__ = ["ESTIMATORS", "list_estimators", "DEFAULT_FIT_THRESHOLD"]

#: Discrete estimators of the linear route, the default first
#: (:data:`condmon.identify.estimate._ESTIMATORS` holds their functions).
ESTIMATORS = ("sriv", "oe", "iv", "arx")

DEFAULT_FIT_THRESHOLD = 90.0
"""Default acceptance threshold on the percentage fit. [%]"""


def list_estimators() -> list[str]:
    """Names accepted by ``method``.

    Example
    -------
    >>> list_estimators()
    ['sriv', 'oe', 'iv', 'arx']
    """
    return list(ESTIMATORS)
