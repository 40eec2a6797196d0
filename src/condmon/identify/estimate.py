"""From one test record to physical parameters: the estimation pipeline (SPEC A3-A5).

record -> validate -> the machine's declaration -> route: linear (discrete
estimate, SRIV by default with closed-loop instruments when the excitation is
recorded -> fit check -> ZOH inverse -> parameters from the symbolic
coefficient map) or inverse model (filtered, differentiated signals -> least
squares) -> physical parameters with standard errors -> plausibility.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from condmon.errors import CondmonError, EstimationError, ModelError
from condmon.identify._common import TFEstimate
from condmon.identify.defaults import ESTIMATORS, list_estimators
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD, FitCheck
from condmon.identify.greybox import choose_route, inverse_route, linear_route
from condmon.identify.ls import arx, iv
from condmon.identify.oe import oe
from condmon.identify.sriv import sriv
from condmon.io.records import Record, validate_record
from condmon.models.machine import Machine
from condmon.models.registry import get_model
from condmon.models.transfer import ContinuousTF

__all__ = ["EstimateResult", "estimate", "estimate_record", "estimate_joint", "list_estimators",
           "DEFAULT_EXCITATION"]

FloatArray = NDArray[np.float64]

#: Excitation columns used when present and not told otherwise.
DEFAULT_EXCITATION = ("yd", "ud")


class Estimator(Protocol):
    def __call__(self, u: ArrayLike, y: ArrayLike, order: int, *, dt: float = ...,
                 excitation: ArrayLike | None = ..., outputs: tuple[str, ...] | None = ...,
                 input_name: str = ...) -> TFEstimate: ...


_ESTIMATORS: dict[str, Estimator] = {"sriv": sriv, "oe": oe, "iv": iv, "arx": arx}
assert tuple(_ESTIMATORS) == ESTIMATORS, "condmon.identify.defaults names every estimator"


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """Physical parameters estimated from one record.

    Attributes
    ----------
    parameters : dict of str to float
        Physical parameters in SI units, in the model's report order (DC motor:
        R [ohm], L [H], Ke [V s/rad], Kt [N m/A], J [kg m^2], D [N m s/rad]).
    std_errors : dict of str to float
        Standard error of each parameter (delta method). [same units]
    covariance : ndarray
        Covariance of the parameters, in the order of ``parameters``.
    fit : FitCheck
        R_T² per output (linear route) or per equation (inverse route),
        percentage fit, accepted or not.
    discrete : TFEstimate or None
        The discrete estimate of the linear route (None for the inverse route).
    continuous : ContinuousTF or None
        Its zero-order-hold continuous equivalent (None when it has none).
    model : str
        Model name.
    constants : dict of str to float
        Known constants used (e.g. gamma = Ke/Kt, gtau). [SI]
    source : str
        Record's source.
    units : dict of str to str
        Unit of each parameter.
    rejection : str or None
        Why no physical parameters could be accepted (no continuous
        equivalent, not physically possible); ``accepted`` is then False.
    route : str
        "linear" or "inverse".
    notes : tuple of str
        What the user should know (the estimator's path, residual checks).
    diagnostics : dict of str to float
        Residual figures: ``nrmse <output>`` (RMS error / RMS of the measured
        signal) and ``whiteness <output>`` (largest normalised
        autocorrelation of the residual at lags 1..20) per output (linear and
        output-error routes) or per equation (inverse route, with ``cutoff_hz``).
    model_source : str or None
        The declaration file of a user's model (None for a shipped model).
    """

    parameters: dict[str, float]
    std_errors: dict[str, float]
    covariance: FloatArray
    fit: FitCheck
    discrete: TFEstimate | None
    continuous: ContinuousTF | None
    model: str
    constants: dict[str, float]
    source: str
    units: dict[str, str]
    rejection: str | None = None
    route: str = "linear"
    notes: tuple[str, ...] = ()
    diagnostics: dict[str, float] = field(default_factory=dict)
    model_source: str | None = None

    @property
    def model_key(self) -> str:
        """What :func:`condmon.models.get_model` takes to find this model again:
        the declaration file of a user's model, else the shipped name."""
        return self.model_source or self.model

    @property
    def gamma(self) -> float:
        """Ke/Kt used (DC-motor models; NaN for others). [-]"""
        return float(self.constants.get("gamma", float("nan")))

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
        """Estimator used ("inverse" for the inverse-model route)."""
        if self.discrete is not None:
            return self.discrete.method
        return "oe" if self.route == "oe" else "idim-ls"

    @property
    def closed_loop_instruments(self) -> bool:
        """Whether instruments came from the excitation signals."""
        return self.discrete.closed_loop_instruments if self.discrete is not None else False

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result (the ``condmon estimate --json`` document); no NaN or inf."""
        def clean(d: Mapping[str, float]) -> dict[str, float | None]:
            return {k: (float(v) if np.isfinite(v) else None) for k, v in d.items()}

        fit = self.fit.fit_percent
        d = self.discrete
        return {
            "source": self.source,
            "model": self.model,
            "route": self.route,
            "parameters": clean(self.parameters),
            "std_errors": clean(self.std_errors),
            "units": self.units,
            "fit_percent": fit if np.isfinite(fit) else None,
            "fits": clean(self.fit.fits_percent),
            "fit_threshold": self.fit.threshold,
            "accepted": self.accepted,
            "reason": self.reason,
            "method": self.method,
            "path": d.route if d is not None else self.method,
            "closed_loop_instruments": self.closed_loop_instruments,
            "iterations": d.iterations if d is not None else 1,
            "converged": d.converged if d is not None else True,
            "gamma": self.gamma if np.isfinite(self.gamma) else None,
            "constants": clean(self.constants),
            "notes": list(self.notes),
            "diagnostics": clean(self.diagnostics),
            "discrete_model": None if d is None else d.to_dict(),
            "continuous_model": None if self.continuous is None else self.continuous.to_dict(),
        }

    def to_frame(self) -> pd.DataFrame:
        """Parameter table: value, standard error, unit."""
        return pd.DataFrame({"value": self.parameters, "std_error": self.std_errors,
                             "unit": self.units})


def _excitation_columns(record: pd.DataFrame | Record, machine: Machine,
                        excitation: Sequence[str] | str | None) -> tuple[str, ...]:
    cols = record.columns if isinstance(record, Record) else list(record.columns)
    if excitation == "auto":
        names = machine.spec.excitation or DEFAULT_EXCITATION
        found = [c for c in names if c in cols]
        if isinstance(record, Record):
            return tuple(found)
        # a recorded but constant excitation (a perturbation switched off) is left out
        return tuple(c for c in found
                     if pd.to_numeric(record[c], errors="coerce").nunique(dropna=True) > 1)
    if excitation is None or isinstance(excitation, str):
        return ()
    return tuple(excitation)


def _required_columns(machine: Machine, route: str) -> tuple[str, ...]:
    """Record columns a route needs (inputs, then sensors)."""
    if route == "oe":
        from condmon.models.semilinear import semilinear_structure  # sympy: only for this route

        s = semilinear_structure(machine)
        return (*s.inputs, *s.sensors)
    if route == "linear":
        lin = machine.linear()
        return (lin.input, *lin.outputs)
    return machine.inverse().columns


def estimate(record: pd.DataFrame, model: str | Machine = "dc-motor", *,
             method: str = "sriv", gamma: float | None = None,
             excitation: Sequence[str] | str | None = "auto",
             fit_threshold: float = DEFAULT_FIT_THRESHOLD,
             columns: Mapping[str, str] | None = None,
             source: str | None = None, route: str | None = None,
             constants: Mapping[str, float] | None = None) -> EstimateResult:
    """Estimate the physical parameters of a machine from one test record.

    Parameters
    ----------
    record : pandas.DataFrame
        Columns ``t`` [s] and the model's input and sensors (DC motor: ``V`` [V],
        ``I`` [A], ``omega`` [rad/s]); optionally the excitation signals.
        Constants in ``record.attrs["constants"]`` (e.g. scalars of a .mat
        file) override the declared ones.
    model : str, path or Machine
        A declared machine: a name from :func:`condmon.models.list_models`
        or a declaration file (.toml).
    method : {"sriv", "oe", "iv", "arx"}
        Discrete estimator of the linear route: SRIV (falls back to
        output-error refinement when its iterations fail), output error
        (maximum likelihood, started from SRIV), basic IV, least squares.
    gamma : float, optional
        Ke/Kt of a DC motor (shorthand for ``constants={"gamma": ...}``). [-]
    excitation : "auto", sequence of str or None
        Excitation columns for closed-loop instruments. "auto" uses the
        declared ones (``yd``, ``ud``) when present; None (or an empty list)
        forces the direct approach.
    fit_threshold : float
        Reject below this percentage fit. [%]
    columns : mapping, optional
        ``{canonical: column}`` renames applied first.
    source : str, optional
        Name of the record in messages and results.
    route : {"auto", "linear", "inverse", "oe"}, optional
        Override the declaration's route.
    constants : mapping, optional
        Known constants overriding the declared ones. [SI]

    Returns
    -------
    EstimateResult

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> res = estimate(simulate_actuator(seed=1))
    >>> res.accepted, res.method, res.closed_loop_instruments, res.route
    (True, 'sriv', True, 'linear')
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    machine.require_estimation()
    if method not in _ESTIMATORS:
        raise ModelError(f"unknown method {method!r}; allowed: {', '.join(_ESTIMATORS)}")
    chosen = choose_route(machine, route)
    df = record.rename(columns={v: k for k, v in columns.items()}) if columns else record
    exc = _excitation_columns(df, machine, excitation) if chosen == "linear" else ()
    n_unknowns = len(machine.spec.unknowns)
    rec = validate_record(df, (*_required_columns(machine, chosen), *exc),
                          input_name=machine.linear().input if chosen == "linear" else None,
                          min_samples=10 * (n_unknowns + 1), source=source)
    consts = dict(df.attrs.get("constants", {}) or {})
    _check_constants(machine, dict(constants or {}), strict=tuple(constants or ()))
    consts.update(constants or {})
    if gamma is not None:
        consts["gamma"] = gamma
    return estimate_record(rec, machine, method=method, excitation=exc,
                           fit_threshold=fit_threshold, route=chosen, constants=consts)


def _oe_start(rec: Sequence[Record], machine: Machine, consts: Mapping[str, float],
              fit_threshold: float) -> tuple[dict[str, float], str]:
    """Starting values of the output-error route: the inverse-model estimate when
    that route fits the model and gives positive-definite answers, else the
    declared values."""
    try:
        inv = inverse_route(rec, machine, constants=consts, fit_threshold=fit_threshold)
    except CondmonError:
        return machine.nominal(), "the declared values"
    if machine.spec.plausibility.check_values(inv.values, machine.units) is None:
        return inv.values, "the inverse-model estimate"
    return machine.nominal(), "the declared values"


def estimate_joint(records: Sequence[pd.DataFrame], model: str | Machine = "dc-motor", *,
                   fit_threshold: float = DEFAULT_FIT_THRESHOLD,
                   columns: Mapping[str, str] | None = None,
                   sources: Sequence[str] | None = None, route: str | None = None,
                   constants: Mapping[str, float] | None = None) -> EstimateResult:
    """Estimate one set of physical parameters from several records at once.

    The records (one sample interval) enter one criterion: the output error
    summed over all of them (each simulated from rest), or one stacked
    inverse-model regression. A linear model takes the output-error route.

    Parameters
    ----------
    records : sequence of pandas.DataFrame
        As for :func:`estimate`.
    model, fit_threshold, columns, route, constants
        As for :func:`estimate`.
    sources : sequence of str, optional
        Names of the records in messages and results.

    Returns
    -------
    EstimateResult
        ``source`` joins the records' names with " + ".

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> res = estimate_joint([simulate_actuator(seed=1), simulate_actuator(seed=2)])
    >>> res.route, res.accepted, res.source
    ('oe', True, 'record 1 + record 2')
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    machine.require_estimation()
    chosen = choose_route(machine, route)
    if chosen == "linear":
        chosen = choose_route(machine, "oe")
    names = list(sources) if sources is not None else [
        str(df.attrs.get("source", f"record {i + 1}")) for i, df in enumerate(records)]
    consts: dict[str, float] = {}
    recs = []
    for df, name in zip(records, names):
        frame = df.rename(columns={v: k for k, v in columns.items()}) if columns else df
        consts.update(dict(frame.attrs.get("constants", {}) or {}))
        recs.append(validate_record(frame, _required_columns(machine, chosen),
                                    min_samples=10 * (len(machine.spec.unknowns) + 1),
                                    source=name))
    consts.update(constants or {})
    return estimate_record(recs, machine, fit_threshold=fit_threshold, route=chosen,
                           constants=consts)


def _check_constants(machine: Machine, constants: Mapping[str, float],
                     strict: Sequence[str] = ()) -> dict[str, float]:
    """Validated constants; names in ``strict`` (given by the user) must be known
    constants of the model, others (a .mat file's scalars) are skipped."""
    known = machine.constants()
    out = {}
    for k, v in constants.items():
        if k not in known:
            if k in strict:
                raise ModelError(f"unknown constant {k!r} for model {machine.name!r}; "
                                 f"known constants: {', '.join(known) or 'none'}")
            continue  # constants of a file that this model does not use
        try:
            val = float(v)
        except (TypeError, ValueError):
            raise ModelError(f"constant {k} must be a number, got {v!r}") from None
        if k == "gamma" and not (math.isfinite(val) and val > 0):
            raise ModelError(f"gamma (Ke/Kt) must be a positive number, got {val!r}")
        if not math.isfinite(val):
            raise ModelError(f"constant {k} must be finite, got {val!r}")
        out[k] = val
    return out


def estimate_record(rec: Record | Sequence[Record], model: str | Machine = "dc-motor", *,
                    method: str = "sriv", gamma: float | None = None,
                    excitation: Sequence[str] = (),
                    fit_threshold: float = DEFAULT_FIT_THRESHOLD, route: str | None = None,
                    constants: Mapping[str, float] | None = None) -> EstimateResult:
    """:func:`estimate` on already validated :class:`~condmon.io.Record` (s).

    Several records are estimated together by the output-error or the
    inverse-model route (a linear model takes the output-error route then).
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    records = [rec] if isinstance(rec, Record) else list(rec)
    if not records:
        raise ModelError("no record to estimate from")
    source = " + ".join(r.source for r in records)
    given = dict(constants or {})
    if gamma is not None:
        given["gamma"] = gamma
    consts = machine.constants(_check_constants(machine, given))
    if not (math.isfinite(fit_threshold) and 0.0 <= fit_threshold <= 100.0):
        raise ModelError(f"the fit threshold must be in 0..100 %, got {fit_threshold!r}")
    spec = machine.spec
    for r in records:
        spec.plausibility.check_timing(r.dt, r.dt * len(r), r.source, machine.name)
    chosen = choose_route(machine, route)
    notes: list[str] = []
    if len(records) > 1:
        if chosen == "linear":
            chosen = choose_route(machine, "oe")
            notes.append("several records: the linear model is estimated by output error")
        notes.append(f"estimated jointly from {len(records)} records")
    diagnostics: dict[str, float] = {}
    discrete = None
    cont = None
    rejection = None
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            if chosen == "linear":
                lin = linear_route(records[0], machine, _ESTIMATORS[method], excitation=excitation,
                                   constants=consts, fit_threshold=fit_threshold)
                values, ucov, fit = lin.values, lin.covariance, lin.fit
                discrete, cont, rejection = lin.discrete, lin.continuous, lin.rejection
                diagnostics = dict(lin.diagnostics)
                notes += list(lin.discrete.notes)
            elif chosen == "oe":
                from condmon.identify.oe_route import oe_route  # sympy, scipy: only this route

                start, how = _oe_start(records, machine, consts, fit_threshold)
                oe_res = oe_route(records, machine, start, constants=consts,
                                  fit_threshold=fit_threshold)
                values, ucov, fit = oe_res.values, oe_res.covariance, oe_res.fit
                diagnostics = oe_res.diagnostics()
                notes.append(f"output error: the declared model simulated with its "
                             f"linear part exact (ZOH), started from {how}, "
                             f"{oe_res.evaluations} optimiser evaluations")
            else:
                inv = inverse_route(records, machine, constants=consts,
                                    fit_threshold=fit_threshold)
                values, ucov, fit = inv.values, inv.covariance, inv.fit
                diagnostics = inv.diagnostics()
                notes.append(f"inverse model (IDIM-LS): zero-phase low-pass at {inv.cutoff:g} Hz, "
                             f"central differences, {inv.samples} samples")
                worst = max(inv.whiteness, key=lambda k: inv.whiteness[k])
                limit = spec.max_residual_correlation
                if inv.whiteness[worst] > limit:
                    rejection = (f"structure mismatch: the residual of {worst} is strongly "
                                 f"correlated ({inv.whiteness[worst]:.2f} > {limit:g}); the "
                                 "model misses part of the dynamics (friction, offset, "
                                 "another mode?)")
    except CondmonError as err:
        # Estimators do not know the file: name it (same error class), once.
        text = str(err)
        raise type(err)(text if text.startswith(source) else f"{source}: {text}") from None
    except (ArithmeticError, np.linalg.LinAlgError, ValueError) as err:
        # The estimators guard every step; this is the last line, never a traceback.
        raise EstimationError(f"{source}: the estimate failed numerically "
                              f"({type(err).__name__}: {err})") from None
    white = {k.split(" ", 1)[1]: v for k, v in diagnostics.items() if k.startswith("whiteness ")}
    if chosen in ("linear", "oe") and white and max(white.values()) > spec.residual_warning:
        worst = max(white, key=lambda k: white[k])
        notes.append(f"possible structure mismatch: the residual of {worst} is correlated "
                     f"({white[worst]:.2f} > {spec.residual_warning:g}); the model may miss "
                     "part of the dynamics" + (f" ({spec.structure_hint})"
                                               if spec.structure_hint else ""))
    names = spec.report
    if rejection is None or rejection.startswith("structure mismatch"):
        params, pcov = machine.report_values({**consts, **values}, ucov)
        vals = np.array([params[k] for k in names])
    else:
        vals = np.full(len(names), np.nan)
        pcov = np.full((len(names), len(names)), np.nan)
    se = np.sqrt(np.clip(np.diag(pcov), 0.0, None))
    if rejection is None:
        rejection = spec.plausibility.check_values(dict(zip(names, vals)), machine.units,
                                                   dict(zip(names, se)))
    if rejection is None and not np.all(np.isfinite(se)):
        rejection = "the standard errors are not finite: the data do not determine the model"
    return EstimateResult(
        parameters={k: float(v) for k, v in zip(names, vals)},
        std_errors={k: float(v) for k, v in zip(names, se)},
        covariance=pcov, fit=fit, discrete=discrete, continuous=cont, model=machine.name,
        constants=consts, source=source, units=machine.units, rejection=rejection,
        route=chosen, notes=tuple(notes), diagnostics=diagnostics, model_source=machine.origin)
