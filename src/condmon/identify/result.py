"""What an estimate of one record is: :class:`EstimateResult`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.identify._common import TFEstimate
from condmon.identify.fit import FitCheck
from condmon.identify.identifiability import Identifiability
from condmon.identify.windows import Window
from condmon.models.transfer import ContinuousTF

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["EstimateResult"]

FloatArray = NDArray[np.float64]


def _clean(d: Mapping[str, float]) -> dict[str, float | None]:
    return {k: (float(v) if np.isfinite(v) else None) for k, v in d.items()}


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """Physical parameters estimated from one record (in one operating regime).

    Attributes
    ----------
    parameters : dict of str to float
        Physical parameters in SI units, in the model's report order (DC motor:
        R [ohm], L [H], Ke [V s/rad], Kt [N m/A], J [kg m^2], D [N m s/rad]).
        A parameter the record does not identify holds the value it was held
        at (see ``held``).
    std_errors : dict of str to float
        Standard error of each parameter (delta method); 0 for a held one. [same units]
    covariance : ndarray
        Covariance of the parameters, in the order of ``parameters``.
    fit : FitCheck
        R_T² per output (linear route), per equation (inverse route) or of
        each balance (steady route), percentage fit, accepted or not.
    discrete : TFEstimate or None
        The discrete estimate of the linear route (None for the others).
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
        equivalent, not physically possible, ``not identifiable: ...``);
        ``accepted`` is then False.
    route : str
        "linear", "inverse", "oe" or "steady".
    notes : tuple of str
        What the user should know (the estimator's path, residual checks,
        constants fixed for the run, how the record was read).
    diagnostics : dict of str to float
        Residual figures: ``nrmse <output>`` (RMS error / RMS of the measured
        signal) and ``whiteness <output>`` (largest normalised
        autocorrelation of the residual at lags 1..20) per output or equation
        (with ``cutoff_hz``, ``samples``, ``windows`` where the route has them).
    model_source : str or None
        The declaration file of a user's model (None for a shipped model).
    regime : str
        The operating regime of the windows used ("" when the machine
        declares none).
    windows : tuple of Window
        The record's windows: the ones used (of this regime) and every other
        with why it was not.
    identifiability : Identifiability or None
        Which unknowns the windows identified (None: not assessed, all).
    held : dict of str to str
        Each reported quantity not identified -> where its value comes from
        (``"baseline"``: the unit's, ``"nominal"``: the declaration's).
    trended : tuple of str
        The reported quantities the record identifies: the ones stored and
        trended (a derived quantity is identified when every unknown it
        depends on is).
    others : tuple of EstimateResult
        The estimates of the record's other regimes, if it has several.
    features : dict of str to (float, float)
        The declared signal features of the record (``[features]``):
        ``{name@regime: (value, batch-means standard error)}``, every
        regime's, on the first regime's estimate (:mod:`condmon.features`).
        [feature units]
    feature_units : dict of str to str
        Unit of each feature, by name.
    conditions : dict of str to (float, float)
        The record's operating conditions (``[conditions]``): a channel's
        statistic per regime (``oil@forward``) or a metadata field (``load``),
        each with its standard error (batch means; 0 for a metadata field).
        [condition units]
    systematic : dict of str to float
        The systematic part of each stored value (keyed as
        :meth:`stored_values`): how far the sensors could move it by drifting
        within their stated accuracy (``[record.columns]``'s ``accuracy``),
        the change of the value when each reading is offset by its accuracy,
        root-sum-square over the sensors. A bound, not a standard deviation:
        a change inside it cannot be told from the sensors' drift
        (:func:`condmon.monitor.generic.judged_config`). ``std_errors`` is the
        record's own noise and says nothing of it. A value no stated accuracy
        moves (a feature of a channel without one) has none. [same units]
    initial_states : dict of str to (float, float, str)
        Simulation-error route: each state's initial value in the record, its
        standard error and how it was set ("estimated", "first sample",
        "declared"); what ``condmon validate`` starts from. [state units]
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
    regime: str = ""
    windows: tuple[Window, ...] = ()
    identifiability: Identifiability | None = None
    held: dict[str, str] = field(default_factory=dict)
    trended: tuple[str, ...] | None = None
    others: tuple[EstimateResult, ...] = ()
    features: dict[str, tuple[float, float]] = field(default_factory=dict)
    feature_units: dict[str, str] = field(default_factory=dict)
    systematic: dict[str, float] = field(default_factory=dict)
    conditions: dict[str, tuple[float, float]] = field(default_factory=dict)
    initial_states: dict[str, tuple[float, float, str]] = field(default_factory=dict)
    smoothing: float | None = None

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
    def identified(self) -> tuple[str, ...]:
        """The reported quantities to store and trend (all when not assessed)."""
        return tuple(self.parameters) if self.trended is None else self.trended

    @property
    def reason(self) -> str | None:
        """Why the test was rejected (None when accepted)."""
        if self.rejection is not None:
            return self.rejection
        if not self.fit.accepted:
            # the inverse route differentiates a filtered record: a cut-off that
            # does not suit it fails where the simulation error would not
            hint = ("; --route simulation fits the model by its simulation error "
                    "instead (no filter, no derivatives; slower), or set [estimation] "
                    "cutoff" if self.route == "inverse" else "")
            return (f"fit {self.fit.fit_percent:.1f} % below the threshold "
                    f"{self.fit.threshold:g} %{hint}")
        return None

    @property
    def not_identifiable(self) -> bool:
        """Whether the record identifies none of the unknowns (retest, never trended)."""
        return (self.rejection or "").startswith("not identifiable")

    @property
    def fit_percent(self) -> float:
        """Percentage fit. [%]"""
        return self.fit.fit_percent

    @property
    def method(self) -> str:
        """Estimator used ("idim-ls" for the inverse route, "steady" for the steady
        one, "simulation-error" for the simulation route)."""
        if self.discrete is not None:
            return self.discrete.method
        return {"oe": "oe", "steady": "steady",
                "simulation": "simulation-error"}.get(self.route, "idim-ls")

    @property
    def closed_loop_instruments(self) -> bool:
        """Whether instruments came from the excitation signals."""
        return self.discrete.closed_loop_instruments if self.discrete is not None else False

    @property
    def regimes(self) -> tuple[EstimateResult, ...]:
        """This estimate and those of the record's other regimes."""
        return (self, *self.others)

    @property
    def usable(self) -> bool:
        """Whether any regime's estimate is accepted (the record is trended)."""
        return any(p.accepted for p in self.regimes)

    def stored_values(self) -> dict[str, tuple[float, float]]:
        """What the history keeps: ``{name: (value, std_error)}``, a regime's
        parameters named ``Tc@forward``. For a usable record the identified
        quantities of each accepted regime; otherwise (kept for the record,
        never trended) every parameter of this estimate that has a value. The
        record's signal features follow (``vib@forward``), whatever its regimes'
        estimates.

        Example
        -------
        >>> from condmon.simulate import simulate_actuator
        >>> from condmon.identify import estimate
        >>> sorted(estimate(simulate_actuator(seed=1)).stored_values())
        ['D', 'J', 'Ke', 'Kt', 'L', 'R']
        """
        from condmon.models.regimes import regime_key

        if not self.usable:
            out = {regime_key(k, self.regime): (v, self.std_errors[k])
                   for k, v in self.parameters.items() if np.isfinite(v)}
        else:
            out = {regime_key(k, p.regime): (p.parameters[k], p.std_errors[k])
                   for p in self.regimes if p.accepted for k in p.identified}
        out.update(self.features)
        return out

    def unit_of(self, key: str) -> str:
        """The unit of a stored quantity (``Tc@forward`` or a feature ``vib@forward``).

        Example
        -------
        >>> from condmon.simulate import simulate_actuator
        >>> from condmon.identify import estimate
        >>> estimate(simulate_actuator(seed=1)).unit_of("R")
        'ohm'
        """
        from condmon.models.regimes import split_key

        name = split_key(key)[0]
        return self.units.get(name, self.feature_units.get(name, ""))

    @property
    def regime_label(self) -> str:
        """The record's regimes, the accepted ones first (``forward`` or
        ``forward; reverse``); "" when the machine declares none."""
        parts = sorted(self.regimes, key=lambda p: not p.accepted)
        return "; ".join(dict.fromkeys(p.regime for p in parts if p.regime))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result (the ``condmon estimate --json`` document); no NaN or inf."""
        fit = self.fit.fit_percent
        d = self.discrete
        idf = self.identifiability
        reasons = idf.reasons if idf is not None else {}
        doc = {
            "source": self.source,
            "model": self.model,
            "route": self.route,
            "regime": self.regime,
            "parameters": _clean(self.parameters),
            "std_errors": _clean(self.std_errors),
            "units": self.units,
            "identifiable": {k: k in self.identified for k in self.parameters},
            "held": {k: {"value": (float(self.parameters[k])
                                   if np.isfinite(self.parameters[k]) else None),
                         "from": src, "reason": reasons.get(
                             k, "given a value for this estimate (--constants)" if src == "given"
                             else "depends on a held unknown")}
                     for k, src in self.held.items()},
            "fit_percent": fit if np.isfinite(fit) else None,
            "fits": _clean(self.fit.fits_percent),
            "fit_threshold": self.fit.threshold,
            "accepted": self.accepted,
            "reason": self.reason,
            "method": self.method,
            "path": d.route if d is not None else self.method,
            "closed_loop_instruments": self.closed_loop_instruments,
            "iterations": d.iterations if d is not None else 1,
            "converged": d.converged if d is not None else True,
            "gamma": self.gamma if np.isfinite(self.gamma) else None,
            "constants": _clean(self.constants),
            "notes": list(self.notes),
            "diagnostics": _clean(self.diagnostics),
            "windows": [w.to_dict() for w in self.windows],
            "identifiability": None if idf is None else idf.to_dict(),
            "discrete_model": None if d is None else d.to_dict(),
            "continuous_model": None if self.continuous is None else self.continuous.to_dict(),
        }
        if self.others:
            doc["other_regimes"] = [o.to_dict() for o in self.others]
        if self.systematic:
            doc["systematic"] = _clean(self.systematic)
        if self.smoothing is not None:   # widened by the simulation route: validate's too
            doc["smoothing"] = self.smoothing
        if self.initial_states:
            doc["initial_states"] = {k: {"value": _clean({"v": v})["v"],
                                         "std_error": _clean({"s": se})["s"], "from": how}
                                     for k, (v, se, how) in self.initial_states.items()}
        if self.conditions:
            doc["conditions"] = {k: {"value": _clean({"v": v})["v"],
                                     "std_error": _clean({"s": se})["s"]}
                                 for k, (v, se) in self.conditions.items()}
        if self.features:
            doc["features"] = {k: {"value": _clean({"v": v})["v"],
                                   "std_error": _clean({"s": se})["s"],
                                   "unit": self.unit_of(k)}
                               for k, (v, se) in self.features.items()}
        return doc

    def to_frame(self) -> pd.DataFrame:
        """Parameter table: value, standard error, unit, identified."""
        import pandas as pd

        return pd.DataFrame({"value": self.parameters, "std_error": self.std_errors,
                             "unit": self.units,
                             "identified": {k: k in self.identified for k in self.parameters}})
