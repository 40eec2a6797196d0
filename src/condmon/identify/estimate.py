"""From one test record to physical parameters: the estimation pipeline (SPEC A3-A5).

record -> validate -> discrete estimate (SRIV by default, closed-loop
instruments when the excitation is recorded) -> fit check -> ZOH inverse ->
physical parameters with standard errors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from condmon.errors import CondmonError, EstimationError, ModelError
from condmon.identify._common import TFEstimate
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD, FitCheck, fit_check
from condmon.identify.ls import arx, iv
from condmon.identify.oe import oe
from condmon.identify.sriv import sriv
from condmon.io.records import Record, validate_record
from condmon.models.conversion import tf_d2c
from condmon.models.registry import get_model
from condmon.models.transfer import ContinuousTF

__all__ = ["EstimateResult", "estimate", "estimate_record", "list_estimators",
           "DEFAULT_EXCITATION"]

FloatArray = NDArray[np.float64]

#: Excitation columns used when present and not told otherwise.
DEFAULT_EXCITATION = ("yd", "ud")


class Estimator(Protocol):
    def __call__(self, u: ArrayLike, y: ArrayLike, order: int, *, dt: float = ...,
                 excitation: ArrayLike | None = ..., outputs: tuple[str, ...] | None = ...,
                 input_name: str = ...) -> TFEstimate: ...


_ESTIMATORS: dict[str, Estimator] = {"sriv": sriv, "oe": oe, "iv": iv, "arx": arx}


def list_estimators() -> list[str]:
    """Names accepted by ``method``."""
    return list(_ESTIMATORS)


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """Physical parameters estimated from one record.

    Attributes
    ----------
    parameters : dict of str to float
        Physical parameters in SI units (DC motor: R [ohm], L [H], Ke [V s/rad],
        Kt [N m/A], J [kg m^2], D [N m s/rad]).
    std_errors : dict of str to float
        Standard error of each parameter (delta method). [same units]
    covariance : ndarray
        Covariance of the parameters, in the order of ``parameters``.
    fit : FitCheck
        R_T² per output, percentage fit, accepted or not.
    discrete : TFEstimate
        The discrete estimate (with its own covariance and notes).
    continuous : ContinuousTF or None
        Its zero-order-hold continuous equivalent (None when it has none).
    model : str
        Physical model name.
    gamma : float
        Model constant used (Ke/Kt). [-]
    source : str
        Record's source.
    units : dict of str to str
        Unit of each parameter.
    rejection : str or None
        Why no physical parameters could be read (e.g. a discrete pole on the
        negative real axis); the parameters are then NaN, ``accepted`` is False
        and the JSON holds ``null``.
    """

    parameters: dict[str, float]
    std_errors: dict[str, float]
    covariance: FloatArray
    fit: FitCheck
    discrete: TFEstimate
    continuous: ContinuousTF | None
    model: str
    gamma: float
    source: str
    units: dict[str, str]
    rejection: str | None = None

    @property
    def accepted(self) -> bool:
        """Whether the test is usable: the fit passed and physical parameters exist."""
        return self.fit.accepted and self.rejection is None

    @property
    def reason(self) -> str | None:
        """Why the test was rejected (None when accepted)."""
        if self.rejection is not None:
            return self.rejection
        if not self.fit.accepted:
            return (f"fit {self.fit.fit_percent:.1f} % below the threshold "
                    f"{self.fit.threshold:g} %")
        return None

    @property
    def fit_percent(self) -> float:
        """Percentage fit. [%]"""
        return self.fit.fit_percent

    @property
    def method(self) -> str:
        """Estimator used."""
        return self.discrete.method

    @property
    def closed_loop_instruments(self) -> bool:
        """Whether instruments came from the excitation signals."""
        return self.discrete.closed_loop_instruments

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result (the ``condmon estimate --json`` document)."""
        def clean(d: dict[str, float]) -> dict[str, float | None]:
            return {k: (v if np.isfinite(v) else None) for k, v in d.items()}

        fit = self.fit.fit_percent
        return {
            "source": self.source,
            "model": self.model,
            "parameters": clean(self.parameters),
            "std_errors": clean(self.std_errors),
            "units": self.units,
            "fit_percent": fit if np.isfinite(fit) else None,
            "fits": clean(self.fit.fits_percent),
            "fit_threshold": self.fit.threshold,
            "accepted": self.accepted,
            "reason": self.reason,
            "method": self.discrete.method,
            "path": self.discrete.route,
            "closed_loop_instruments": self.discrete.closed_loop_instruments,
            "iterations": self.discrete.iterations,
            "converged": self.discrete.converged,
            "gamma": self.gamma,
            "notes": list(self.discrete.notes),
            "discrete_model": self.discrete.to_dict(),
            "continuous_model": None if self.continuous is None else self.continuous.to_dict(),
        }

    def to_frame(self) -> pd.DataFrame:
        """Parameter table: value, standard error, unit."""
        return pd.DataFrame({"value": self.parameters, "std_error": self.std_errors,
                             "unit": self.units})


def _excitation_columns(record: pd.DataFrame | Record,
                        excitation: Sequence[str] | str | None) -> tuple[str, ...]:
    cols = record.columns if isinstance(record, Record) else list(record.columns)
    if excitation == "auto":
        return tuple(c for c in DEFAULT_EXCITATION if c in cols)
    if excitation is None or isinstance(excitation, str):
        return ()
    return tuple(excitation)


def estimate(record: pd.DataFrame, model: str = "dc-motor", *, method: str = "sriv",
             gamma: float | None = None, excitation: Sequence[str] | str | None = "auto",
             fit_threshold: float = DEFAULT_FIT_THRESHOLD,
             columns: Mapping[str, str] | None = None,
             source: str | None = None) -> EstimateResult:
    """Estimate the physical parameters of a machine from one test record.

    Parameters
    ----------
    record : pandas.DataFrame
        Columns ``t`` [s] and the model's input and outputs (DC motor: ``V`` [V],
        ``I`` [A], ``omega`` [rad/s]); optionally the excitation signals.
    model : str
        Physical model, see :func:`condmon.models.list_models`.
    method : {"sriv", "oe", "iv", "arx"}
        Estimator: SRIV (falls back to output-error refinement when its
        iterations fail), output error (maximum likelihood, started from SRIV),
        basic IV, least squares.
    gamma : float, optional
        Ke/Kt; the model's configured default if omitted. [-]
    excitation : "auto", sequence of str or None
        Excitation columns for closed-loop instruments. "auto" uses ``yd`` and
        ``ud`` when present; None (or an empty list) forces the direct approach.
    fit_threshold : float
        Reject below this percentage fit. [%]
    columns : mapping, optional
        ``{canonical: column}`` renames applied first.
    source : str, optional
        Name of the record in messages and results.

    Returns
    -------
    EstimateResult

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> res = estimate(simulate_actuator(seed=1))
    >>> res.accepted, res.method, res.closed_loop_instruments
    (True, 'sriv', True)
    """
    spec = get_model(model)
    if method not in _ESTIMATORS:
        raise ModelError(f"unknown method {method!r}; allowed: {', '.join(_ESTIMATORS)}")
    df = record.rename(columns={v: k for k, v in columns.items()}) if columns else record
    exc = _excitation_columns(df, excitation)
    rec = validate_record(df, (spec.input, *spec.outputs, *exc), input_name=spec.input,
                          min_samples=10 * spec.order * (1 + len(spec.outputs)),
                          source=source)
    return estimate_record(rec, model, method=method, gamma=gamma, excitation=exc,
                           fit_threshold=fit_threshold)


def estimate_record(rec: Record, model: str = "dc-motor", *, method: str = "sriv",
                    gamma: float | None = None, excitation: Sequence[str] = (),
                    fit_threshold: float = DEFAULT_FIT_THRESHOLD) -> EstimateResult:
    """:func:`estimate` on an already validated :class:`~condmon.io.Record`."""
    spec = get_model(model)
    g = spec.gamma if gamma is None else float(gamma)
    if not (math.isfinite(g) and g > 0):
        raise ModelError(f"gamma (Ke/Kt) must be a positive number, got {g!r}")
    if not (math.isfinite(fit_threshold) and 0.0 <= fit_threshold <= 100.0):
        raise ModelError(f"the fit threshold must be in 0..100 %, got {fit_threshold!r}")
    spec.plausibility.check_timing(rec.dt, rec.dt * len(rec), rec.source, spec.name)
    u = rec[spec.input]
    y = rec.stack(spec.outputs)
    r = rec.stack(excitation) if excitation else None
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            est = _ESTIMATORS[method](u, y, spec.order, dt=rec.dt, excitation=r,
                                      outputs=spec.outputs, input_name=spec.input)
    except CondmonError as err:
        # Estimators do not know the file: name it (same error class).
        raise type(err)(f"{rec.source}: {err}") from None
    except (ArithmeticError, np.linalg.LinAlgError, ValueError) as err:
        # The estimators guard every step; this is the last line, never a traceback.
        raise EstimationError(f"{rec.source}: the estimate failed numerically "
                              f"({type(err).__name__}: {err})") from None
    fit = fit_check(est.model, u, y, fit_threshold)
    names = spec.parameters
    cont: ContinuousTF | None = None
    rejection = None
    try:
        cont = tf_d2c(est.model)
        values, pcov = spec.from_discrete(est.model, est.covariance, g)
    except ModelError as err:  # ConversionError included: no physical reading exists
        rejection = f"no physical parameters: {err}"
        values = np.full(len(names), np.nan)
        pcov = np.full((len(names), len(names)), np.nan)
    se = np.sqrt(np.clip(np.diag(pcov), 0.0, None))
    if rejection is None:
        rejection = spec.plausibility.check_values(dict(zip(names, values)), spec.units)
    if rejection is None and not np.all(np.isfinite(se)):
        rejection = "the standard errors are not finite: the data do not determine the model"
    return EstimateResult(
        parameters={k: float(v) for k, v in zip(names, values)},
        std_errors={k: float(v) for k, v in zip(names, se)},
        covariance=pcov, fit=fit, discrete=est, continuous=cont, model=spec.name,
        gamma=g, source=rec.source, units=dict(spec.units), rejection=rejection)
