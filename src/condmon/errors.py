"""Exceptions and warnings raised by condmon.

Every error raised on purpose derives from :class:`CondmonError` and also from the
matching built-in exception, so callers may catch either::

    try:
        condmon.estimate(record)
    except condmon.DataError as err:      # or ValueError
        print(err)
"""

from __future__ import annotations

__all__ = [
    "CondmonError",
    "DataError",
    "MissingColumnsError",
    "ConfigError",
    "ModelError",
    "ConversionError",
    "EstimationError",
    "CondmonWarning",
    "DataWarning",
    "ConvergenceWarning",
]


class CondmonError(Exception):
    """Base class of every error condmon raises on purpose."""


class DataError(CondmonError, ValueError):
    """A record is unusable: missing column, NaN, bad time base, too short, ...

    The message names the file (when known) and the column.
    """


class MissingColumnsError(DataError):
    """A record lacks columns a model or a column mapping needs.

    Attributes
    ----------
    missing : tuple of str
        The columns looked for and not found.
    columns : tuple of str
        The columns the record has (under the names looked up).
    """

    def __init__(self, message: str, missing: tuple[str, ...] = (),
                 columns: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.missing = missing
        self.columns = columns


class ConfigError(CondmonError, ValueError):
    """A configuration file (parameters, rules, mappings) is missing or invalid."""


class ModelError(CondmonError, ValueError):
    """A model is ill-posed: wrong order, unknown name, non-physical coefficients."""


class ConversionError(ModelError):
    """A discrete model has no continuous-time equivalent under zero-order hold
    (a pole at zero or on the negative real axis)."""


class EstimationError(CondmonError, ArithmeticError):
    """An estimator could not produce an estimate (singular normal equations, ...)."""


class CondmonWarning(UserWarning):
    """Base class of condmon's warnings."""


class DataWarning(CondmonWarning):
    """The data are usable but suspicious (e.g. a large share of saturated samples)."""


class ConvergenceWarning(CondmonWarning):
    """An iterative estimator stopped at its iteration cap without converging."""
