"""A machine declared as data, ready for estimation: the declaration plus its
``[estimation]`` table, and the structure condmon derives from the equations.

Two structures are derived symbolically (sympy), with no code per machine:

- :class:`LinearStructure` — when every state derivative is linear in the
  states and one input, and every sensor reads a linear combination of states:
  the common-denominator transfer functions ``C adj(sI - A) B / det(sI - A)``
  and the map from their coefficients to the parameters.
- :class:`InverseStructure` — when the equations are linear in the unknown
  parameters (nonlinear in the signals allowed: ``sign``, offsets): each
  equation ``den·x' - num = 0`` written as ``Σ θ_k φ_k(signals) = known(signals)``.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError, ModelError
from condmon.io.rig import RecordSettings
from condmon.models import derived_cache
from condmon.models.declared import PlantModel, substituted_equations, symbols_of
from condmon.models.plausibility import (
    IdentifiabilityLimits, Plausibility,
)
from condmon.models.features import ConditionSpec, FeatureSpec
from condmon.models.regimes import RegimeSpec
from condmon.models.shooting import SimulationSettings

if TYPE_CHECKING:
    import sympy as sp

    from condmon.models.inverse import InverseStructure

# sympy is imported where a structure is derived: the linear structure and the
# derived quantities of a declaration are kept in condmon.models.derived_cache,
# so estimating a cached model needs no sympy.

__all__ = ["EstimationSpec", "Machine", "LinearStructure", "ROUTES"]

FloatArray = NDArray[np.float64]

#: Folder of the shipped declarations and their monitoring files.
DATA_DIR = Path(__file__).resolve().parents[1] / "data"

#: Estimation routes a declaration may ask for.
ROUTES = ("auto", "linear", "inverse", "oe", "steady", "simulation")


@dataclass(frozen=True)
class EstimationSpec:
    """The ``[estimation]`` table of a declaration.

    Attributes
    ----------
    unknowns : tuple of str
        Parameters estimated; every other parameter is a known constant.
    report : tuple of str
        Quantities reported, in order (unknowns and derived).
    derived : dict of str to (str, str)
        ``name -> (equation, unit)`` of quantities computed from parameters.
    route : {"auto", "linear", "inverse", "oe", "steady", "simulation"}
        "steady": the state equations as balances (derivatives zero) over
        the steady windows of a record (:mod:`condmon.identify.steady_route`);
        "simulation": the simulation error of any declared model, unmeasured
        states included (:mod:`condmon.identify.simulation_route`).
    order : int or None
        Discrete model order for the linear route (default: number of states).
    excitation : tuple of str
        Closed-loop excitation columns, used when the record has them.
    cutoff : float or None
        Zero-phase low-pass cut-off before differentiation (inverse route);
        None: a tenth of the Nyquist frequency. [Hz]
    decimate : int
        Keep one sample in ``decimate`` for the inverse-model regression.
    plausibility : Plausibility
    residual_warning : float
        Linear and output-error routes: an output residual whose largest
        normalised autocorrelation (lags 1..20) exceeds this is noted as a
        possible structure mismatch (the estimate is kept). [-]
    structure_hint : str
        What the note suggests then (e.g. a declaration with the missing term).
    identifiability : IdentifiabilityLimits
        When an unknown counts as identifiable; the others are held at the
        unit's baseline value or at nominal.
    steady_tolerance : float
        Steady route: a window whose derivative terms (``J dω/dt`` with the
        held or nominal ``J``) exceed this fraction of the balance's RMS is not
        steady and not used. [-]
    simulation : SimulationSettings
        Simulation-error route: initial states, shooting segments, starts
        (:mod:`condmon.models.shooting`).
    cycle : tuple of str
        The regimes one test holds (``[estimation] cycle``): records are taken
        together, in time order, until they hold a used window of each, and
        estimated as one test (a stroke each way tells a friction from a load
        torque and from the gauges' offsets). Empty: a test is one record.
    deadband : float
        Inverse route: rows where the argument of a ``sign``/``abs`` is within
        this fraction of its RMS are left out (static friction at standstill
        is anywhere within ±Fc). [-]
    max_residual_correlation : float
        Inverse route: largest normalised autocorrelation of an equation's
        residual (lags 1..20 at twice the cut-off) before the estimate is
        rejected as a structure mismatch (the model misses part of the
        dynamics). [-]
    """

    unknowns: tuple[str, ...]
    report: tuple[str, ...]
    derived: dict[str, tuple[str, str]] = field(default_factory=dict)
    route: str = "auto"
    order: int | None = None
    excitation: tuple[str, ...] = ()
    cutoff: float | None = None
    decimate: int = 1
    plausibility: Plausibility = field(default_factory=Plausibility)
    max_residual_correlation: float = 0.8
    deadband: float = 0.01
    residual_warning: float = 0.15
    structure_hint: str = ""
    identifiability: IdentifiabilityLimits = IdentifiabilityLimits()
    steady_tolerance: float = 0.1
    simulation: SimulationSettings = SimulationSettings()
    cycle: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class Machine:
    """A declared machine: the plant model and how to estimate and monitor it.

    ``origin`` is the declaration file of a user's model (None for a shipped
    one); ``rules`` and ``breakpoints`` the model's own rule base and monitor
    breakpoints files (None: generic monitoring from the baseline's spread,
    :mod:`condmon.monitor.generic`); ``record`` how the rig writes its files
    (the ``[record]`` table); ``regimes`` its operating regimes; ``features``
    the signal features it declares (``[features]``, :mod:`condmon.models.features`);
    ``conditions`` its operating conditions (``[conditions]``), the covariates
    a healthy value is fitted against (:mod:`condmon.monitor.conditions`);
    ``indicators`` the :class:`~condmon.models.indicators.IndicatorModel` of
    an indicator declaration (its indicators are the plant's parameters,
    nothing is estimated: values are imported).

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> m = get_model("dc-motor")
    >>> m.spec.unknowns, m.spec.report
    (('R', 'L', 'Kt', 'J', 'D'), ('R', 'L', 'Ke', 'Kt', 'J', 'D'))
    >>> m.linear().order, m.linear().outputs
    (2, ('I', 'omega'))
    """

    plant: PlantModel
    spec: EstimationSpec
    origin: str | None = None
    rules: str | None = None
    breakpoints: str | None = None
    record: RecordSettings = field(default_factory=RecordSettings)
    regimes: RegimeSpec = field(default_factory=RegimeSpec)
    features: tuple[FeatureSpec, ...] = ()
    conditions: tuple[ConditionSpec, ...] = ()
    indicators: Any = None

    @property
    def monitored_generically(self) -> bool:
        """Whether the declaration lacks its breakpoints or rules (no
        ``[monitor]`` table): they come from the baseline's spread and are
        generic (:mod:`condmon.monitor.generic`)."""
        return self.rules is None or self.breakpoints is None

    @property
    def name(self) -> str:
        """The model's name."""
        return self.plant.name

    @property
    def monitored(self) -> tuple[str, ...]:
        """What is baselined, checked and named in rules: the reported
        parameters, then the declared signal features (``[features]``)."""
        return (*self.spec.report, *(f.name for f in self.features))

    @property
    def sessions(self) -> tuple[ConditionSpec, ...]:
        """The declared conditions that are the time since a session started
        (``since = "session start"``): the unit's history gives their value."""
        return tuple(c for c in self.conditions if c.session_gap is not None)

    @property
    def feature_units(self) -> dict[str, str]:
        """Unit of every declared signal feature."""
        return {f.name: f.unit for f in self.features}

    @property
    def monitored_units(self) -> dict[str, str]:
        """Unit of everything monitored: the reported parameters and the features."""
        return {**self.units, **self.feature_units}

    @property
    def units(self) -> dict[str, str]:
        """Unit of every reported quantity."""
        units = self.plant.parameter_units()
        units.update({k: u for k, (_, u) in self.spec.derived.items()})
        return {k: units.get(k, "") for k in self.spec.report}

    def constants(self, overrides: Mapping[str, float] | None = None) -> dict[str, float]:
        """Known parameters (not estimated), with ``overrides`` applied. [SI]"""
        values = {p.name: p.value for p in self.plant.parameters
                  if p.name not in self.spec.unknowns}
        for k, v in (overrides or {}).items():
            if k in values:
                values[k] = float(v)
        return values

    def nominal(self) -> dict[str, float]:
        """Declared values of the unknowns (the starting point of a search). [SI]"""
        return {p.name: p.value for p in self.plant.parameters if p.name in self.spec.unknowns}

    def require_estimation(self) -> None:
        """Raise :class:`ModelError` when the declaration says nothing to estimate."""
        if self.indicators is not None:
            raise ModelError(f"model {self.name!r} ({self.plant.source}) is an indicator "
                             "declaration: its values are measured elsewhere and stored with "
                             f"`condmon import TABLE --model {self.origin or self.name}`, not "
                             "estimated from records")
        if not self.spec.unknowns:
            faults = [p.name for p in self.plant.parameters if p.fault]
            isolate = (f"; its fault candidates ({', '.join(faults)}) are found by running "
                       f"the model beside the record: condmon isolate {self.origin or self.name} "
                       "RECORD" if faults else "")
            raise ModelError(f"model {self.name!r} ({self.plant.source}) declares no "
                             "[estimation] table: add one naming the parameters to "
                             f"estimate{isolate}")

    def linear(self) -> LinearStructure:
        """The linear structure; :class:`ModelError` (with the reason) if the model is not linear."""
        return _linear(self)

    def inverse(self) -> InverseStructure:
        """The inverse-model structure; :class:`ModelError` if not linear in the parameters."""
        from condmon.models.inverse import inverse_structure

        return inverse_structure(self)

    def derived_functions(self) -> dict[str, tuple[sp.Expr, Callable[..., Any]]]:
        """Each derived quantity as (expression, fn(params dict) -> value)."""
        return _derived(self)

    def report_jacobian(self, params: Mapping[str, float]
                        ) -> tuple[dict[str, float], FloatArray]:
        """Reported quantities and their gradient with respect to the unknowns.

        ``params`` holds unknowns and constants. A reported name that is
        neither an unknown nor derived is a constant (an unknown fixed for a
        run): its value, a zero gradient.

        Returns
        -------
        values : dict of str to float
            In ``spec.report`` order. [SI]
        jacobian : ndarray, shape (len(report), len(unknowns))
        """
        unknowns = self.spec.unknowns
        rows = []
        values = {}
        for name in self.spec.report:
            if name in unknowns:
                g = np.zeros(len(unknowns))
                g[unknowns.index(name)] = 1.0
                values[name] = float(params[name])
            elif name in self.spec.derived:
                value, gradient = derived_numeric(self)[name]
                values[name] = float(value(params))
                g = gradient(params)
            else:
                values[name] = float(params[name])
                g = np.zeros(len(unknowns))
            rows.append(np.broadcast_to(np.asarray(g, dtype=np.float64), (len(unknowns),)))
        return values, np.array(rows).reshape(len(rows), len(unknowns))

    def report_values(self, params: Mapping[str, float], cov: FloatArray
                      ) -> tuple[dict[str, float], FloatArray]:
        """Reported quantities and their covariance from the unknowns' estimates.

        ``params`` holds unknowns and constants; ``cov`` is the unknowns'
        covariance (order of ``spec.unknowns``). Derived quantities take the
        delta method with their exact gradient.
        """
        values, G = self.report_jacobian(params)
        return values, G @ cov @ G.T

    def with_fixed(self, names: Mapping[str, float] | Sequence[str]) -> Machine:
        """This machine with some unknowns known for a run (``--constants R=1.2``):
        they become constants, still reported; the others are estimated.

        Raises
        ------
        ModelError
            When every unknown would be fixed.

        Example
        -------
        >>> from condmon.models.registry import get_model
        >>> get_model("dc-motor").with_fixed(["D"]).spec.unknowns
        ('R', 'L', 'Kt', 'J')
        """
        fixed = tuple(u for u in self.spec.unknowns if u in set(names))
        return self if not fixed else _fixed(self, fixed)


@functools.lru_cache(maxsize=32)
def _fixed(machine: Machine, fixed: tuple[str, ...]) -> Machine:
    import dataclasses

    unknowns = tuple(u for u in machine.spec.unknowns if u not in fixed)
    if not unknowns:
        raise ModelError(f"model {machine.name!r}: every unknown is fixed by --constants "
                         f"({', '.join(fixed)}); nothing is left to estimate")
    spec = dataclasses.replace(machine.spec, unknowns=unknowns)
    return dataclasses.replace(machine, spec=spec)


# -- the linear structure ---------------------------------------------------------------


@dataclass(frozen=True)
class LinearStructure:
    """Transfer functions of a linear declared model and their coefficient map.

    Attributes
    ----------
    order : int
        Number of states n (the common denominator's degree).
    input : str
        The input column.
    outputs : tuple of str
        Sensor (record column) names, in numerator order.
    coefficients : sequence of sympy.Expr
        ``[a_1..a_n, b_11..b_1n, ..., b_m1..b_mn]`` of
        ``(b_j1 s^(n-1) + ... + b_jn) / (s^n + a_1 s^(n-1) + ... + a_n)``,
        as functions of the parameters (derived on first access when the
        structure came from the cache).
    free : tuple of int
        Indices of the coefficients not identically zero (the equations solved).
    values : callable
        ``values(unknowns, constants) -> coefficient vector`` (free ones).
    jacobian : callable
        ``jacobian(unknowns, constants) -> d coefficients / d unknowns``.
    """

    order: int
    input: str
    outputs: tuple[str, ...]
    coefficients: Sequence[sp.Expr]
    free: tuple[int, ...]
    values: Callable[[FloatArray, FloatArray], FloatArray]
    jacobian: Callable[[FloatArray, FloatArray], FloatArray]
    # the lambdified functions behind values and jacobian (kept in the cache)
    raw: tuple[Callable[..., Any], ...] = field(default=(), repr=False, compare=False)


class _Deferred(Sequence["sp.Expr"]):
    """A sequence computed on first access (the symbolic coefficients of a cached
    linear structure, derived only when someone reads them)."""

    def __init__(self, compute: Callable[[], Sequence[sp.Expr]]) -> None:
        self._compute = compute
        self._items: tuple[sp.Expr, ...] | None = None

    def _get(self) -> tuple[sp.Expr, ...]:
        if self._items is None:
            self._items = tuple(self._compute())
        return self._items

    @overload
    def __getitem__(self, i: int) -> sp.Expr: ...

    @overload
    def __getitem__(self, i: slice) -> Sequence[sp.Expr]: ...

    def __getitem__(self, i: int | slice) -> sp.Expr | Sequence[sp.Expr]:
        return self._get()[i]

    def __len__(self) -> int:
        return len(self._get())

    def __iter__(self) -> Iterator[sp.Expr]:
        return iter(self._get())

    def __repr__(self) -> str:
        return repr(self._get())


def _spec_item(machine: Machine, kind: str) -> str:
    """Cache item name of a structure that depends on the ``[estimation]`` table."""
    spec = machine.spec
    return f"{kind}:" + json.dumps([spec.unknowns, sorted(spec.derived.items())])


def _wrap(fn: Callable[..., Any]) -> Callable[[FloatArray, FloatArray], FloatArray]:
    return lambda p, k: np.asarray(fn(list(p), list(k)), dtype=np.float64)


def _probe(machine: Machine) -> tuple[list[float], list[float]]:
    """(unknowns, constants) at their declared values: where cached functions are checked."""
    unknowns = machine.nominal()
    consts = machine.constants()
    return ([unknowns[k] for k in machine.spec.unknowns],
            [consts[p] for p in machine.plant.parameter_names if p not in machine.spec.unknowns])


def _dump_linear(machine: Machine, lin: LinearStructure) -> dict[str, Any] | None:
    if len(lin.raw) != 2:
        return None
    probe = _probe(machine)
    values, jacobian = (derived_cache.portable(fn, *probe) for fn in lin.raw)
    if values is None or jacobian is None:
        return None
    return {"order": lin.order, "input": lin.input, "outputs": list(lin.outputs),
            "free": list(lin.free), "values": values, "jacobian": jacobian}


def _restore_linear(machine: Machine, data: dict[str, Any]) -> LinearStructure:
    f_val = derived_cache.restore_function(data["values"])
    f_jac = derived_cache.restore_function(data["jacobian"])
    return LinearStructure(
        int(data["order"]), str(data["input"]), tuple(str(o) for o in data["outputs"]),
        _Deferred(lambda: _derive_linear(machine).coefficients),
        tuple(int(i) for i in data["free"]), _wrap(f_val), _wrap(f_jac), (f_val, f_jac))


def _is_linear_in(expr: sp.Expr, syms: list[sp.Symbol]) -> bool:
    import sympy as sp

    if expr.has(sp.sign, sp.Abs, sp.Min, sp.Max, sp.Heaviside):
        return False
    for s in syms:
        d = sp.diff(expr, s)
        if any(sp.diff(d, t) != 0 for t in syms):
            return False
    return bool(sp.simplify(expr.subs({s: 0 for s in syms})) == 0)


@functools.lru_cache(maxsize=32)
def _linear(machine: Machine) -> LinearStructure:
    return derived_cache.cached(
        derived_cache.plant_key(machine.plant), _spec_item(machine, "linear"),
        lambda: _derive_linear(machine), lambda lin: _dump_linear(machine, lin),
        lambda data: _restore_linear(machine, data))


def _derive_linear(machine: Machine) -> LinearStructure:
    import sympy as sp

    plant, spec = machine.plant, machine.spec
    sym = symbols_of(plant)
    _, derivs, readings = substituted_equations(plant)
    xs = [sym[n] for n in plant.state_names]
    used_inputs = [u for u in plant.input_names
                   if any(e.has(sym[u]) for e in derivs.values())]
    where = f"{plant.source}: the linear route"
    if len(used_inputs) != 1:
        raise ModelError(f"{where} needs exactly one input in the state equations, found "
                         f"{len(used_inputs)} ({', '.join(used_inputs) or 'none'})")
    u = sym[used_inputs[0]]
    for name, e in derivs.items():
        if not _is_linear_in(e, [*xs, u]):
            raise ModelError(f"{where}: d{name}/dt = {e} is not linear in the states and "
                             f"the input (no offset, sign or abs)")
    for name, e in readings.items():
        if e.has(u) or not _is_linear_in(e, xs):
            raise ModelError(f"{where}: sensor {name!r} = {e} is not a linear combination "
                             "of the states")
    n = len(xs)
    A = sp.Matrix([[sp.diff(derivs[a], x) for x in xs] for a in plant.state_names])
    B = sp.Matrix([sp.diff(derivs[a], u) for a in plant.state_names])
    C = sp.Matrix([[sp.diff(readings[s], x) for x in xs] for s in plant.sensor_names])
    s = sp.Symbol("s")
    M = s * sp.eye(n) - A
    den = sp.Poly(sp.expand(M.det(method="berkowitz")), s)
    lead = den.coeffs()[0]
    adjB = M.adjugate() * B
    den_c = [sp.simplify(den.coeff_monomial(s ** (n - k)) / lead) for k in range(1, n + 1)]
    coeffs = list(den_c)
    for j in range(C.rows):
        num = sp.Poly(sp.expand((C[j, :] * adjB)[0, 0]), s)
        if num.degree() >= n:
            raise ModelError(f"{where}: sensor {plant.sensor_names[j]!r} has direct "
                             "feedthrough from the input")
        coeffs += [sp.simplify(num.coeff_monomial(s ** (n - k)) / lead) for k in range(1, n + 1)]
    free = tuple(i for i, c in enumerate(coeffs) if c != 0)
    unknowns = [sym[k] for k in spec.unknowns]
    missing = [k for k in spec.unknowns if not any(c.has(sym[k]) for c in coeffs)]
    if missing:
        raise ModelError(f"{where}: {', '.join(missing)} do not appear in the transfer "
                         "functions and cannot be estimated from them")
    known = [sym[p] for p in plant.parameter_names if p not in spec.unknowns]
    vec = sp.Matrix([coeffs[i] for i in free])
    jac = vec.jacobian(unknowns)
    f_val = sp.lambdify((unknowns, known), list(vec), modules="numpy", cse=True)
    f_jac = sp.lambdify((unknowns, known), jac.tolist(), modules="numpy", cse=True)
    if len(free) < len(unknowns):
        raise ModelError(f"{where}: {len(free)} transfer-function coefficients cannot "
                         f"determine {len(unknowns)} unknowns; fix some as constants")
    return LinearStructure(n, used_inputs[0], plant.sensor_names, tuple(coeffs), free,
                           _wrap(f_val), _wrap(f_jac), (f_val, f_jac))


# -- derived quantities -----------------------------------------------------------------


@functools.lru_cache(maxsize=32)
def _derived(machine: Machine) -> dict[str, tuple[sp.Expr, Callable[..., Any]]]:
    import sympy as sp

    from condmon.models.expressions import parse_expression

    sym = symbols_of(machine.plant)
    params = {k: sym[k] for k in machine.plant.parameter_names}
    out = {}
    for name, (eq, _) in machine.spec.derived.items():
        where = f"{machine.plant.source}[estimation.derived.{name}]"
        expr = parse_expression(eq, params, where)
        if expr.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
            raise ConfigError(f"{where}: {eq!r} is infinite or undefined as written: a division "
                              "by zero?")
        fn = sp.lambdify(list(params.values()), expr, modules="numpy")
        names = list(params)
        out[name] = (expr, (lambda f, ns: lambda d: f(*[d[k] for k in ns]))(fn, names))
    return out


DerivedRaw = dict[str, tuple[Callable[..., Any], Callable[..., Any]]]


def _derive_raw(machine: Machine) -> DerivedRaw:
    """Each derived quantity and its gradient with respect to the unknowns, as
    numpy functions of every parameter (declaration order)."""
    import sympy as sp

    sym = symbols_of(machine.plant)
    params = [sym[k] for k in machine.plant.parameter_names]
    out = {}
    for name, (expr, _) in _derived(machine).items():
        grad = [sp.diff(expr, sym[u]) for u in machine.spec.unknowns]
        out[name] = (sp.lambdify(params, expr, modules="numpy"),
                     sp.lambdify(params, grad, modules="numpy"))
    return out


def _dump_derived(machine: Machine, raw: DerivedRaw) -> dict[str, Any] | None:
    probe = [p.value for p in machine.plant.parameters]
    out = {}
    for name, fns in raw.items():
        kept = [derived_cache.portable(fn, *probe) for fn in fns]
        if kept[0] is None or kept[1] is None:
            return None
        out[name] = kept
    return out


@functools.lru_cache(maxsize=32)
def derived_numeric(machine: Machine) -> dict[str, tuple[Callable[[Mapping[str, float]], Any],
                                                          Callable[[Mapping[str, float]],
                                                                   FloatArray]]]:
    """Each derived quantity as (value, gradient with respect to the unknowns),
    functions of a parameter dict; from the cache when the declaration is in it."""
    raw = derived_cache.cached(
        derived_cache.plant_key(machine.plant), _spec_item(machine, "derived"),
        lambda: _derive_raw(machine), lambda r: _dump_derived(machine, r),
        lambda data: {k: (derived_cache.restore_function(v[0]),
                          derived_cache.restore_function(v[1])) for k, v in data.items()})
    names = list(machine.plant.parameter_names)

    def value(f: Callable[..., Any]) -> Callable[[Mapping[str, float]], Any]:
        return lambda d: f(*[d[k] for k in names])

    def gradient(f: Callable[..., Any]) -> Callable[[Mapping[str, float]], FloatArray]:
        return lambda d: np.asarray(f(*[d[k] for k in names]), dtype=np.float64)

    return {k: (value(fv), gradient(fg)) for k, (fv, fg) in raw.items()}
