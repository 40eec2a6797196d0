"""The steady route: a declared machine's equations as balances over steady windows.

In a window where the machine runs steadily (an actuator's stroke at constant
speed, a transmission at one operating point) the state derivatives are
about zero and each state equation becomes an algebraic balance,
``Σ θ_k φ_k(signals) = known(signals)`` with the derivative terms gone (an
inertia drops out). Averaging a window's samples gives one row per equation
and window; the rows of every window of a record, or of several records,
are solved together by weighted least squares for the unknowns they
identify (:func:`~condmon.identify.regression.identified_lstsq`): a single
stroke identifies one friction level, strokes at several speeds and both
directions its viscous and Coulomb parts and a load torque.

- **Weights.** Each window's row is weighted by the standard error of its
  mean residual, taken by batch means of the residual with its straight-line
  trend removed: the residual of a steady window is slow, not white (its
  samples are not independent), and a drift across the window (a load that
  varies with the angle) is a repeatable part of the balance, seen in the
  fit, not noise of its mean.
- **Steadiness.** A window whose derivative terms (at the held or declared
  values, e.g. ``J dω/dt``) exceed ``steady_tolerance`` of the balance's RMS is
  not steady and is not used.
- **Fit.** What the route predicts is the balance, so the fit is measured on
  it, sample by sample over the windows used: ``1 − Σ e² / Σ known²`` per
  equation (not the R² of a derivative that is about zero, nor of a
  balance whose value hardly varies).

Machines whose balances need a state that is neither measured nor derived
(the hydrostatic transmission's motor pressure) are estimated on window means
by :func:`condmon.identify.steady_state.estimate_steady_states`, which solves
those states with the one steady-state solver the fault isolation uses.

Written for condmon (no maintained package derives steady balances from a
declared model).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.identify.fit import FitCheck, residual_figures
from condmon.identify.greybox import RouteResult
from condmon.identify.identifiability import Identifiability
from condmon.identify.inverse_route import absent_unknowns, evaluate
from condmon.identify.regression import identified_lstsq
from condmon.io.records import Record
from condmon.models.machine import Machine

__all__ = ["SteadyRouteResult", "steady_route", "steady_output_error", "batch_se"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Fewest samples of a window the route uses.
MIN_WINDOW_SAMPLES = 10


@dataclass(frozen=True, eq=False)
class SteadyRouteResult(RouteResult):
    """Outcome of the steady route (see :class:`~condmon.identify.greybox.RouteResult`).

    ``fit`` is ``1 − Σe²/Σknown²`` of each balance over the samples of the
    windows used; ``nrmse`` the RMS residual over the RMS of the balance.

    Attributes
    ----------
    windows : int
        Windows used.
    samples : int
        Samples in them.
    unsteady : dict of (int, int) to str
        ``(record, window)`` -> why a window offered was not steady (not used).
    """

    windows: int = 0
    samples: int = 0
    unsteady: dict[tuple[int, int], str] = field(default_factory=dict)

    def diagnostics(self) -> dict[str, float]:
        """The shared figures, with ``windows`` and ``samples``."""
        return {"windows": float(self.windows), "samples": float(self.samples),
                **super().diagnostics()}


def batch_se(x: FloatArray, batches: int = 10) -> float:
    """Standard error of the mean of a correlated series, by batch means.

    The series is cut into ``batches`` contiguous batches (fewer for a short
    one, at least 2); the standard deviation of their means over the square
    root of their number estimates the standard error when the correlation
    is shorter than a batch.

    Example
    -------
    >>> x = np.random.default_rng(0).standard_normal(10000)
    >>> 0.5 < batch_se(x) / (1 / 100) < 1.5     # white noise: about std/sqrt(n)
    True
    """
    n = int(x.size)
    nb = int(max(2, min(batches, n // 20)))
    if n < 2 * nb:
        return float(np.std(x) / np.sqrt(max(n, 1)))
    means = np.array([b.mean() for b in np.array_split(x, nb)])
    return float(np.std(means, ddof=1) / np.sqrt(nb))


def _detrended(x: FloatArray) -> FloatArray:
    """``x`` less its least-squares straight line."""
    t = np.arange(x.size, dtype=np.float64)
    t -= t.mean()
    denom = float(t @ t)
    slope = float(t @ (x - x.mean())) / denom if denom > 0 else 0.0
    return np.asarray(x - x.mean() - slope * t, dtype=np.float64)


@dataclass(frozen=True)
class _Window:
    record: int
    index: int
    rows: IntArray
    phi: FloatArray        # (n_eq, n_rows, p) static regressors per sample
    known: FloatArray      # (n_eq, n_rows) static known side per sample


def steady_route(signals: Sequence[Mapping[str, FloatArray]],
                 windows: Sequence[Sequence[IntArray]], machine: Machine, *,
                 constants: Mapping[str, float] | None = None,
                 hold: Mapping[str, float] | None = None, fit_threshold: float = 90.0,
                 source: str = "record") -> SteadyRouteResult:
    """Estimate a machine's unknowns from the balances of its steady windows.

    Parameters
    ----------
    signals : sequence of mapping
        Per record, its :func:`~condmon.identify.inverse_route.route_signals`.
    windows : sequence of sequence of ndarray
        Per record, the rows of each window offered (one regime's).
    machine : Machine
        Its equations must be linear in the unknowns with every signal
        measured or derived (an inverse structure).
    constants : mapping, optional
        Values overriding the declared known constants. [SI]
    hold : mapping, optional
        Values of the unknowns the windows do not identify (default: the
        declared ones); also the values the steadiness check uses. [SI]
    fit_threshold : float
        [%]
    source : str
        The record(s), named in messages.

    Returns
    -------
    SteadyRouteResult
        With ``windows == 0`` and nothing identifiable when no window offered
        is steady (``unsteady`` says why).
    """
    import sympy as sp

    spec = machine.spec
    inv = machine.inverse()
    consts = machine.constants(constants)
    held = {**machine.nominal(), **dict(hold or {})}
    names = spec.unknowns
    p = len(names)
    zero = {s: 0 for eq in inv.equations for s in
            (*eq.known.free_symbols, *(x for _, phi in eq.terms for x in phi.free_symbols))
            if str(s).startswith("d_")}
    kept: list[_Window] = []
    unsteady: dict[tuple[int, int], str] = {}
    for i, (sig, wins) in enumerate(zip(signals, windows)):
        for j, rows in enumerate(wins):
            if rows.size < MIN_WINDOW_SAMPLES:
                unsteady[(i, j)] = f"{rows.size} samples (fewer than {MIN_WINDOW_SAMPLES})"
                continue
            phi = np.zeros((len(inv.equations), rows.size, p))
            known = np.zeros((len(inv.equations), rows.size))
            worst = 0.0
            for e, eq in enumerate(inv.equations):
                dynamic = np.zeros(rows.size)
                for unknown, term in eq.terms:
                    static = term.xreplace(zero)
                    if static != 0:
                        phi[e, :, names.index(unknown)] += evaluate(static, sig, consts, rows)
                    if static != term:
                        dynamic += held[unknown] * evaluate(term - static, sig, consts, rows)
                known_static = eq.known.xreplace(zero)
                known[e] = evaluate(known_static, sig, consts, rows)
                if known_static != eq.known:
                    dynamic -= evaluate(sp.expand(eq.known - known_static), sig, consts, rows)
                scale = float(np.sqrt(np.mean(known[e] ** 2)))
                if scale > 0:
                    worst = max(worst, float(np.mean(np.abs(dynamic))) / scale)
            if worst > spec.steady_tolerance:
                unsteady[(i, j)] = (f"not steady: the derivative terms are {100 * worst:.3g} % "
                                    f"of the balance (limit {100 * spec.steady_tolerance:g} %)")
                continue
            kept.append(_Window(i, j, rows, phi, known))
    if not kept:  # nothing to estimate from: every unknown held, no fit
        why = "; ".join(sorted(set(unsteady.values()))) or "no window offered"
        idf = Identifiability(names, (), {u: f"no steady window ({why})" for u in names})
        return SteadyRouteResult(dict(held), np.zeros((p, p)),
                                 FitCheck({}, float("nan"), float(fit_threshold), False), {}, {},
                                 identifiability=idf, windows=0, samples=0, unsteady=unsteady)
    n_eq = len(inv.equations)

    def rows_of(theta: FloatArray | None) -> tuple[list[FloatArray], list[FloatArray],
                                                   list[FloatArray]]:
        """Window means per equation and their weights (1/se)."""
        blocks, rhs, weights = [], [], []
        for e in range(n_eq):
            X = np.array([w.phi[e].mean(axis=0) for w in kept])
            y = np.array([w.known[e].mean() for w in kept])
            se = []
            for w in kept:
                series = w.known[e] - (w.phi[e] @ theta if theta is not None else 0.0)
                floor = 1e-9 * max(float(np.sqrt(np.mean(w.known[e] ** 2))), 1e-300)
                se.append(max(batch_se(_detrended(series)), floor))
            blocks.append(X)
            rhs.append(y)
            weights.append(1.0 / np.array(se))
        return blocks, rhs, weights

    absent = absent_unknowns(machine, steady=True)
    # an unknown declared 0 (a load torque, an offset) has no typical magnitude: a
    # baseline's mean near 0 is none either, and scaled by it a precise estimate
    # would read as a huge relative error; it takes the balance's own scale
    nominal = machine.nominal()
    scales = {n: (held[n] if nominal.get(n, 0.0) != 0.0 else 0.0) for n in names}
    theta: FloatArray | None = None
    fit_ = None
    for _ in range(2):  # weights from the balance alone, then from its residual
        blocks, rhs, weights = rows_of(theta)
        fit_ = identified_lstsq(blocks, rhs, names, scales, held, source=source,
                                limits=spec.identifiability, absent=absent, weights=weights)
        theta = np.array([fit_.values[n] for n in names])
    assert fit_ is not None and theta is not None
    r2, nrmse, white = {}, {}, {}
    for e, eq in enumerate(inv.equations):
        known = np.concatenate([w.known[e] for w in kept])
        resid = known - np.concatenate([w.phi[e] @ theta for w in kept])
        total = float(np.sum(known ** 2))
        name = f"balance {eq.state}"
        r2[name] = 1.0 - float(np.sum(resid ** 2)) / total if total > 0 else float("-inf")
        figures = residual_figures(known, resid)
        nrmse[name] = float(np.sqrt(np.mean(resid ** 2)) / np.sqrt(np.mean(known ** 2))) \
            if total > 0 else float("inf")
        white[name] = figures.whiteness
    fit_pct = 100.0 * float(np.mean(list(r2.values())))
    fit = FitCheck(r2, fit_pct, float(fit_threshold), bool(fit_pct >= fit_threshold))
    samples = int(sum(w.rows.size for w in kept))
    return SteadyRouteResult(fit_.values, fit_.covariance, fit, nrmse, white,
                             identifiability=fit_.identifiability, windows=len(kept),
                             samples=samples, unsteady=unsteady)


def steady_spans(u: FloatArray, y: FloatArray, rows: IntArray, sensors: Sequence[str],
                 t: FloatArray, tolerance: float = 0.1) -> tuple[list[IntArray], str]:
    """The steady spans of an offered window, and why there is none.

    Steady means the derivatives are near zero: the known inputs stay at one
    operating point (:func:`~condmon.simulate.plant.operating_segments`, 2 %),
    so a window is cut where an input moves; and in each piece of at least
    ``MIN_WINDOW_SAMPLES`` samples the outputs do not drift: the means of its
    two halves differ by at most 3 standard errors (batch means of the
    detrended halves), or by at most ``tolerance`` (the declaration's
    ``steady_tolerance``) of how far the output moves over the same time when
    the record moves it (the 95th percentile over the record): a drift the
    noise cannot hide but that is slow beside the machine's own dynamics is
    steady. Else its first half (the settling) is left out and the rest tested
    again.

    Example
    -------
    >>> t = np.arange(200.0)
    >>> u = np.r_[np.zeros(100), np.ones(100)][:, None]
    >>> y = np.r_[np.zeros(100), 1 - np.exp(-np.arange(100) / 15)][:, None]
    >>> y = y + 0.001 * np.random.default_rng(0).standard_normal(y.shape)
    >>> spans, _ = steady_spans(u, y, np.arange(200), ["y"], t)
    >>> [(int(s[0]), int(s[-1])) for s in spans]
    [(0, 99), (150, 199)]
    >>> steady_spans(np.sin(t / 3)[:, None], y, np.arange(200), ["y"], t)[1][:28]
    'the inputs move: no span of '
    """
    from condmon.simulate.plant import operating_segments

    if rows.size < MIN_WINDOW_SAMPLES:
        return [], f"{rows.size} samples (fewer than {MIN_WINDOW_SAMPLES})"
    starts = operating_segments(u[rows]) if u.shape[1] else np.array([0])
    pieces = [rows[a:b] for a, b in zip(starts, [*starts[1:], rows.size])]
    pieces = [p for p in pieces if p.size >= MIN_WINDOW_SAMPLES]
    if not pieces:
        return [], (f"the inputs move: no span of {MIN_WINDOW_SAMPLES} samples at one "
                    f"operating point between {t[rows[0]]:g} and {t[rows[-1]]:g} s")
    spans: list[IntArray] = []
    worst = ""
    for piece in pieces:
        for part in (piece, piece[piece.size // 2:]):
            if part.size < MIN_WINDOW_SAMPLES:
                break
            drift = _drift(y, part, tolerance)
            if drift is None:
                spans.append(part)
                break
            c, change, se = drift
            worst = (f"{sensors[c]} drifts by {change:.3g} within {t[part[0]]:g}-"
                     f"{t[part[-1]]:g} s (more than 3 standard errors, {3 * se:.3g}): not "
                     "steady")
    return spans, ("" if spans else f"the outputs drift in each of the {len(pieces)} span(s) "
                                    f"at one operating point, e.g. {worst}")


def _drift(y: FloatArray, part: IntArray, tolerance: float) -> tuple[int, float, float] | None:
    """The first output that drifts within ``part`` (see :func:`steady_spans`):
    (column, difference of the half means, its standard error); None when none does."""
    half = part.size // 2
    for c in range(y.shape[1]):
        a, b = y[part[:half], c], y[part[half:], c]
        se = float(np.hypot(batch_se(_detrended(a)), batch_se(_detrended(b))))
        se = max(se, 1e-12 * (float(np.max(np.abs(y[part, c]))) + 1e-300))
        change = float(np.mean(b) - np.mean(a))
        if abs(change) <= 3.0 * se:
            continue
        moves = np.abs(y[half:, c] - y[:-half, c]) if y.shape[0] > half else np.zeros(1)
        if abs(change) > tolerance * float(np.percentile(moves, 95)):
            return c, change, se
    return None


def _settled(spans: list[IntArray], why: str, x: FloatArray, states: Sequence[str],
             t: FloatArray, tolerance: float) -> tuple[list[IntArray], str]:
    """The spans in which the model, run on the record's inputs at the held
    values, has settled: each state moves by at most ``tolerance`` of its range
    over the record (an input held for less than the machine's time constant
    leaves the states moving, however still the outputs look)."""
    span_x = np.ptp(x, axis=0)
    kept: list[IntArray] = []
    for rows in spans:
        moved = np.abs(x[rows[-1]] - x[rows[0]])
        bad = np.flatnonzero(moved > tolerance * np.where(span_x > 0, span_x, np.inf))
        if bad.size == 0:
            kept.append(rows)
            continue
        j = int(bad[0])
        why = (f"the model's state {states[j]} still moves by {moved[j]:.3g} within "
               f"{t[rows[0]]:g}-{t[rows[-1]]:g} s (more than {100 * tolerance:g} % of its range "
               f"over the record, {span_x[j]:.3g}): not steady")
    return kept, ("" if kept else why)


def steady_output_error(records: Sequence[Record], windows: Sequence[Sequence[IntArray]],
                        machine: Machine, *, constants: Mapping[str, float] | None = None,
                        hold: Mapping[str, float] | None = None, fit_threshold: float = 90.0,
                        source: str = "record") -> SteadyRouteResult:
    """The steady route of a machine whose balances need states neither measured
    nor derived (a transmission's motor pressure): in each window the model's
    whole steady state is solved (the fault isolation's steady-state solver,
    :func:`~condmon.identify.steady_state.fit_steady_states`) and the unknowns
    fitted so its sensor readings match the window means, each weighted by its
    batch-means standard error. The fit is ``1 − Σ(predicted − mean)²/Σ mean²``
    per sensor over the windows.

    Parameters
    ----------
    records : sequence of Record
        With every sensor column; an input column is used when present (else
        the input's nominal value and the test's schedule).
    windows : sequence of sequence of ndarray
        Per record, the rows of each window offered.
    machine, constants, hold, fit_threshold, source
        As for :func:`steady_route`.

    Returns
    -------
    SteadyRouteResult
    """
    import pandas as pd

    from condmon.identify.steady_state import SteadyWindow, fit_steady_states
    from condmon.simulate.plant import input_signals, integrate

    spec = machine.spec
    held = {**machine.nominal(), **dict(hold or {})}
    plant = machine.plant.with_parameters({**machine.constants(constants), **held})
    compiled = plant.compile()
    sensors = list(plant.sensor_names)
    steady: list[SteadyWindow] = []
    unsteady: dict[tuple[int, int], str] = {}
    used = 0
    for i, (rec, wins) in enumerate(zip(records, windows)):
        t = rec["t"]
        frame = pd.DataFrame({k: v for k, v in rec.columns.items() if k in plant.input_names})
        u = input_signals(plant, t, frame)
        y = rec.stack(sensors)
        tol = spec.steady_tolerance
        if not any(steady_spans(u, y, w, sensors, t, tol)[0] for w in wins):
            for j, w in enumerate(wins):   # no steady span: no need to simulate the record
                unsteady[(i, j)] = steady_spans(u, y, w, sensors, t, tol)[1]
            continue
        x = integrate(compiled, t, u)
        for j, offered in enumerate(wins):
            spans, why = steady_spans(u, y, offered, sensors, t, tol)
            spans, why = _settled(spans, why, x, plant.state_names, t, tol)
            if not spans:
                unsteady[(i, j)] = why
                continue
            for rows in spans:
                used += rows.size
                se = np.array([max(batch_se(_detrended(y[rows, c])),
                                   1e-12 * (abs(y[rows, c]).max() + 1e-300))
                               for c in range(len(sensors))])
                steady.append(SteadyWindow(float(t[rows[0]]), float(t[rows[-1]]),
                                           u[rows].mean(axis=0), y[rows].mean(axis=0), se,
                                           x[rows[-1]].copy()))
    names = spec.unknowns
    p = len(names)
    if not steady:
        why = "; ".join(sorted(set(unsteady.values()))) or "no window offered"
        idf = Identifiability(names, (), {u: f"no steady window ({why})" for u in names})
        return SteadyRouteResult(dict(held), np.zeros((p, p)),
                                 FitCheck({}, float("nan"), float(fit_threshold), False), {}, {},
                                 identifiability=idf, windows=0, samples=0, unsteady=unsteady)
    fit_ = fit_steady_states(plant, names, steady, hold=held, limits=spec.identifiability)
    r2, nrmse = {}, {}
    resid = fit_.misfit.reshape(len(steady), len(sensors)) * np.array([w.std_error
                                                                       for w in steady])
    means = np.array([w.mean for w in steady])
    for c, name in enumerate(sensors):
        total = float(np.sum(means[:, c] ** 2))
        r2[name] = 1.0 - float(np.sum(resid[:, c] ** 2)) / total if total > 0 else float("-inf")
        nrmse[name] = float(np.sqrt(np.mean(resid[:, c] ** 2) / np.mean(means[:, c] ** 2))) \
            if total > 0 else float("inf")
    fit_pct = 100.0 * float(np.mean(list(r2.values())))
    fit = FitCheck(r2, fit_pct, float(fit_threshold),
                   bool(fit_pct >= fit_threshold and fit_.converged))
    samples = used
    return SteadyRouteResult(fit_.values, fit_.covariance, fit, nrmse, {},
                             identifiability=fit_.identifiability, windows=len(steady),
                             samples=samples, unsteady=unsteady)
