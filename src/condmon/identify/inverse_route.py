"""The inverse-model route: IDIM-LS on filtered, differentiated signals.

For equations linear in the unknown parameters but not in the signals
(Coulomb friction ``sign(v)``, offsets): every signal is low-passed with a
zero-phase Butterworth filter, the unmeasured derivatives are taken by central
differences, and ``Σ θ_k φ_k = known`` is solved by weighted least squares
(the inverse dynamic identification model, IDIM-LS) over the rows of the
record's usable windows, for the unknowns those rows identify; standard
errors from the residual variance.

:func:`route_signals` (the filtered and derived signals) and
:func:`evaluate` (an equation's term on them) are shared with the steady
route and with the windows' conditions.

Written for condmon: no maintained Python package derives the regression from
a declared model (IDIM-LS is the standard method for robot and axis dynamics).

References
----------
.. [1] A. Janot, M. Gautier, M. Brunot, "Data set and reference models of EMPS",
   Nonlinear System Identification Benchmarks, 2019.
.. [2] M. Gautier, "Dynamic identification of robots with power model", ICRA 1997.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from condmon.errors import EstimationError
from condmon.identify.fit import FitCheck, residual_figures
from condmon.identify.greybox import RouteResult
from condmon.identify.regression import identified_lstsq
from condmon.io.records import Record
from condmon.models.declared import substituted_equations, symbols_of
from condmon.models.inverse import InverseStructure
from condmon.models.machine import Machine
from condmon.simulate.recorded import fastest_rate

if TYPE_CHECKING:
    import sympy as sp

__all__ = ["InverseRouteResult", "inverse_route", "route_signals", "evaluate", "fastest_mode",
           "route_cutoff", "filter_edge", "absent_unknowns"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class InverseRouteResult(RouteResult):
    """Outcome of the inverse-model route (see :class:`~condmon.identify.greybox.RouteResult`).

    ``fit`` compares each equation's measured (filtered, differentiated) state
    derivative with the derivative the estimated model predicts; ``whiteness``
    is taken at twice the cut-off (the residual's bandwidth).

    Attributes
    ----------
    cutoff : float
        Low-pass cut-off used. [Hz]
    samples : int
        Rows of the regression.
    widening : float
        Largest factor by which the residuals' correlation widened a standard
        error over the white-noise bound (Newey–West). [-]
    bandwidth : float
        Bartlett bandwidth of that estimate. [rows]
    """

    cutoff: float
    samples: int
    widening: float = 1.0
    bandwidth: float = 0.0

    def diagnostics(self) -> dict[str, float]:
        """The shared figures, with ``cutoff_hz``, ``samples``, ``se_widening``
        and ``se_bandwidth_rows``."""
        return {"cutoff_hz": self.cutoff, "samples": float(self.samples),
                "se_widening": self.widening, "se_bandwidth_rows": self.bandwidth,
                **super().diagnostics()}


def _lowpass(x: FloatArray, cutoff: float, fs: float) -> FloatArray:
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, cutoff, fs=fs, output="sos")
    return np.asarray(sosfiltfilt(sos, x), dtype=np.float64)


def route_cutoff(machine: Machine, fs: float, source: str) -> float:
    """The declared low-pass cut-off, else a tenth of the Nyquist frequency. [Hz]

    Raises
    ------
    EstimationError
        A cut-off not below the Nyquist frequency.
    """
    cutoff = machine.spec.cutoff if machine.spec.cutoff is not None else 0.1 * fs / 2.0
    if not cutoff < 0.5 * fs:
        raise EstimationError(f"{source}: the low-pass cut-off {cutoff:g} Hz is not below the "
                              f"Nyquist frequency {0.5 * fs:g} Hz")
    return float(cutoff)


def filter_edge(fs: float, cutoff: float) -> int:
    """Samples left out at both ends of a record after zero-phase filtering."""
    return int(math.ceil(3.0 * fs / cutoff))


def fastest_mode(machine: Machine, values: Mapping[str, float], consts: Mapping[str, float],
                 sig: Mapping[str, FloatArray]) -> float:
    """The fastest mode of the estimated model [Hz]: the largest eigenvalue
    magnitude of its state equations' Jacobian (central differences), over
    2π, at the signals' RMS (a typical operating point, away from the zero of
    a friction's sign). NaN where it cannot be evaluated.

    A mode faster than the route's low-pass cut-off acts in the band the
    filter takes away: a DC motor whose L/R is one sample (133 Hz, cut-off
    100 Hz) had its inductance read 6 % high, 18 standard errors, accepted.

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> sig = {"I": np.full(10, 2.0), "omega": np.full(10, 100.0), "V": np.full(10, 12.0)}
    >>> round(fastest_mode(get_model("dc-motor-coulomb"), {}, {}, sig))   # about R/L/2π
    125
    """
    c = machine.plant.compile()
    states, inputs = c.model.state_names, c.model.input_names

    def rms(name: str) -> float:
        v = sig.get(name)
        return float(np.sqrt(np.mean(np.square(v)))) if v is not None and len(v) else 0.0

    x0 = np.array([rms(n) for n in states])
    u0 = np.array([rms(n) for n in inputs])
    return fastest_rate(c, x0, u0, c.parameter_vector({**consts, **values})) / (2.0 * math.pi)


def route_signals(rec: Record, machine: Machine, cutoff: float) -> dict[str, FloatArray]:
    """A record's signals as the equations name them: measured states and the
    inputs low-passed, states derived from measured ones (a speed from an
    angle) and every state's derivative ``d_<state>`` by central differences.

    Parameters
    ----------
    rec : Record
    machine : Machine
        Its model must have an inverse structure (linear in the unknowns).
    cutoff : float
        Zero-phase low-pass cut-off. [Hz]

    Returns
    -------
    dict of str to ndarray
    """
    import sympy as sp

    plant = machine.plant
    inv = machine.inverse()
    fs = 1.0 / rec.dt
    column_of = {str(e): sensor for sensor, e in substituted_equations(plant)[2].items()
                 if isinstance(e, sp.Symbol)}
    sig: dict[str, FloatArray] = {}
    for state in inv.signals:
        if state in column_of:
            sig[state] = _lowpass(rec[column_of[state]], cutoff, fs)
    for state, of in inv.derivation.items():
        if state not in sig and of in sig:
            sig[state] = np.gradient(sig[of], rec.dt)
    for i in plant.inputs:
        if i.name in rec.columns:
            u = np.asarray(rec[i.name], dtype=np.float64)
            if i.intersample == "zoh":
                # Held over each sample, what acts around a sample's time is on
                # average half a sample older than the sample: the mean of each
                # sample and the one before puts it back on the samples' times.
                # Read as it is, the half-sample lead biased a pendulum's damping
                # by 3 % (its gravity torque's lead reads as damping).
                u = np.r_[u[:1], 0.5 * (u[1:] + u[:-1])]
            sig[i.name] = _lowpass(u, cutoff, fs)
    for state in list(sig):
        if state in plant.state_names:
            sig[f"d_{state}"] = np.gradient(sig[state], rec.dt)
    return sig


def absent_unknowns(machine: Machine, steady: bool = False) -> dict[str, str]:
    """Unknowns that appear in no term the route keeps, with the reason (in a
    steady balance, those multiplying a derivative only)."""
    inv = machine.inverse()
    present: set[str] = set()
    for eq in inv.equations:
        for name, phi in eq.terms:
            if not steady or not any(str(s).startswith("d_") for s in phi.free_symbols):
                present.add(name)
    why = ("the windows used are steady (derivatives zero): it does not appear in the "
           "balance" if steady else "it appears in no equation the route uses")
    return {u: why for u in machine.spec.unknowns if u not in present}


def _edge_rows(rec: Record, machine: Machine, cutoff: float, sig: Mapping[str, FloatArray],
               consts: Mapping[str, float], rows: IntArray | None) -> IntArray:
    """The rows of a record the regression uses: inside the filter's edges,
    one in ``decimate``, within ``rows`` (the usable windows), and away from
    standstill (an argument of ``sign``/``abs`` near zero)."""
    spec = machine.spec
    fs = 1.0 / rec.dt
    edge = filter_edge(fs, cutoff)
    keep = np.arange(edge, len(rec) - edge, spec.decimate)
    if rows is not None:
        keep = np.intersect1d(keep, rows)
    # Rows where the argument of a sign/abs is near zero (an axis standing
    # still: static friction anywhere within +-Fc) are left out.
    for arg in _switch_arguments(machine.inverse()):
        a = evaluate(arg, sig, consts, keep)
        rms = float(np.sqrt(np.mean(a ** 2))) if a.size else 0.0
        keep = keep[np.abs(a) > spec.deadband * rms]
    return keep


def _switch_arguments(inv: InverseStructure) -> list[sp.Expr]:
    """Arguments of the sign/abs functions in the equations (unique)."""
    import sympy as sp

    found: list[sp.Expr] = []
    for eq in inv.equations:
        for expr in (*(phi for _, phi in eq.terms), eq.known):
            for f in expr.atoms(sp.sign, sp.Abs):
                if f.args[0] not in found:
                    found.append(f.args[0])
    return found


def evaluate(expr: sp.Expr, sig: Mapping[str, FloatArray], consts: Mapping[str, float],
             rows: IntArray) -> FloatArray:
    """``expr`` on the signals' ``rows`` (constants by value), shape ``(rows.size,)``.

    Raises
    ------
    EstimationError
        A name that is neither a signal nor a constant.
    """
    import sympy as sp

    names = sorted(str(s) for s in expr.free_symbols)
    args: list[FloatArray | float] = []
    for n in names:
        if n in sig:
            args.append(sig[n][rows])
        elif n in consts:
            args.append(float(consts[n]))
        else:
            raise EstimationError(f"signal {n!r} is not available for the inverse model")
    fn = sp.lambdify([sp.Symbol(n, real=True) for n in names], expr, modules="numpy")
    with np.errstate(all="ignore"):
        val = np.asarray(fn(*args), dtype=np.float64)
    return np.broadcast_to(val, (rows.size,)).astype(np.float64)


def inverse_route(rec: Record | Sequence[Record], machine: Machine, *,
                  constants: Mapping[str, float] | None = None,
                  fit_threshold: float = 90.0,
                  rows: Sequence[IntArray | None] | None = None,
                  signals: Sequence[Mapping[str, FloatArray]] | None = None,
                  hold: Mapping[str, float] | None = None) -> InverseRouteResult:
    """Inverse-model least squares (IDIM-LS) on filtered and differentiated signals.

    Parameters
    ----------
    rec : Record or sequence of Record
        Validated record(s) with every sensor and input column the equations
        use; several records (one sample interval) are stacked into one
        regression.
    machine : Machine
    constants : mapping, optional
        Values overriding the declared known constants. [SI]
    fit_threshold : float
        [%]
    rows : sequence of ndarray or None, optional
        Per record, the rows of its usable windows (None: every row).
    signals : sequence of mapping, optional
        Per record, its :func:`route_signals` (computed when not given).
    hold : mapping, optional
        Values of the unknowns the rows do not identify (default: declared). [SI]

    Returns
    -------
    InverseRouteResult
        ``identifiability`` says which unknowns were estimated.

    Raises
    ------
    EstimationError
        Too few usable samples, regressors that are not finite.
    """
    spec, plant = machine.spec, machine.plant
    records = [rec] if isinstance(rec, Record) else list(rec)
    fs = 1.0 / records[0].dt
    if any(abs(r.dt * fs - 1.0) > 1e-3 for r in records):
        raise EstimationError("records estimated together must share one sample interval: "
                              + ", ".join(f"{r.source} {r.dt:.6g} s" for r in records))
    source = ", ".join(r.source for r in records)
    cutoff = route_cutoff(machine, fs, records[0].source)
    consts = machine.constants(constants)
    sym = symbols_of(plant)
    sigs = list(signals) if signals is not None else \
        [route_signals(r, machine, cutoff) for r in records]
    wanted = list(rows) if rows is not None else [None] * len(records)
    prepared = [(s, _edge_rows(r, machine, cutoff, s, consts, w))
                for r, s, w in zip(records, sigs, wanted)]
    n_rows = sum(int(r.size) for _, r in prepared)
    if n_rows < 10 * len(spec.unknowns):
        raise EstimationError(f"{source}: {n_rows} usable samples after filtering are too "
                              f"few for {len(spec.unknowns)} unknowns")
    inv = machine.inverse()
    blocks, rhs = [], []
    for eq in inv.equations:
        X = np.zeros((n_rows, len(spec.unknowns)))
        for unknown, phi in eq.terms:
            X[:, spec.unknowns.index(unknown)] += np.concatenate(
                [evaluate(phi, sig, consts, r) for sig, r in prepared])
        blocks.append(X)
        rhs.append(np.concatenate([evaluate(eq.known, sig, consts, r) for sig, r in prepared]))
    held = {**machine.nominal(), **dict(hold or {})}
    fit_ = identified_lstsq(blocks, rhs, spec.unknowns, held, held, source=source,
                            limits=spec.identifiability, absent=absent_unknowns(machine))
    # Fit of each equation on the measured (filtered, differentiated) state
    # derivative against the derivative the estimated model predicts.
    values = {**consts, **fit_.values}
    derivs = substituted_equations(plant)[1]
    step = max(1, int(round(fs / (2.0 * cutoff * spec.decimate))))
    r2, nrmse, white = {}, {}, {}
    for eq in inv.equations:
        name = f"d{eq.state}/dt"
        model = derivs[eq.state].xreplace({sym[k]: v for k, v in values.items()})
        meas = np.concatenate([sig[f"d_{eq.state}"][r] for sig, r in prepared])
        pred = np.concatenate([evaluate(model, sig, consts, r) for sig, r in prepared])
        e = meas - pred
        figures = residual_figures(meas, e)
        r2[name], nrmse[name] = figures.r2, figures.nrmse
        white[name] = residual_figures(meas[::step], e[::step]).whiteness
    fit_pct = 100.0 * float(np.mean(list(r2.values())))
    fit = FitCheck(r2, fit_pct, float(fit_threshold), bool(fit_pct >= fit_threshold))
    return InverseRouteResult(fit_.values, fit_.covariance, fit, nrmse, white, float(cutoff),
                              n_rows, fit_.widening, fit_.bandwidth,
                              identifiability=fit_.identifiability)
