"""Plant models declared as data: parameters, inputs, states, sensors, equations.

A declaration (``condmon/data/hst.toml`` is the shipped example) is read once,
validated (every name known, every equation parsed, every sensor's noise
positive) and kept as a frozen :class:`PlantModel`. From it condmon derives, with
no code per machine, the simulator (:meth:`PlantModel.compile`), the steady-state
equations (derivatives set to zero) and the structure used by the fault
signature matrix (:mod:`condmon.diagnose.structure`).

Optional parts of a declaration:

- ``range = [low, high]`` on a parameter: the values an estimate of it may take
  (a suspect's estimate outside is rejected); on an input: the span of the
  signal (a record's input column far outside is refused).
- ``[smoothing] eps = ...``: width of the regularisation of the non-smooth
  functions (``sign``, ``abs``, ``min``, ``max``; see
  :func:`~condmon.models.expressions.smoothed`) in the simulator, in the unit
  of their arguments; 0 keeps them exact. Default: ``smoothing_eps`` of the
  ``[simulation]`` settings (``condmon/data/isolation.toml``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError
from condmon.io.config import load_default
from condmon.models import derived_cache
from condmon.models.excitation import Excitation, parse_excitation

if TYPE_CHECKING:
    import sympy as sp

# sympy (and condmon.models.expressions, built on it) is imported where the
# equations are first needed: a declaration whose derived structure is in the
# cache (condmon.models.derived_cache) is used without it.

__all__ = ["Parameter", "Input", "Variable", "State", "Sensor", "InputStep", "BuiltInTest",
           "PlantModel", "CompiledModel", "plant_from_doc", "smoothing_width",
           "equations_of", "substituted_equations", "symbols_of"]

FloatArray = NDArray[np.float64]

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class Parameter:
    """A model parameter: ``value`` [unit]; ``fault`` marks a candidate fault;
    ``range`` the plausible values of an estimate [unit] (None: not declared)."""

    name: str
    value: float
    unit: str = ""
    description: str = ""
    fault: bool = False
    range: tuple[float, float] | None = None


@dataclass(frozen=True)
class Input:
    """A known input signal; ``nominal`` is a parameter's name or a number [unit];
    ``range`` the signal's plausible span [unit]; ``intersample`` how a record's
    samples of it act between sample times: ``"zoh"`` held over each sample (a
    controller's command through a DAC; condmon's simulations take every input
    so), ``"bl"`` the values at the sample times of a smooth signal (a measured
    force or current) — the names of MATLAB's ``InterSample``."""

    name: str
    nominal: str | float
    unit: str = ""
    description: str = ""
    range: tuple[float, float] = (-math.inf, math.inf)
    intersample: str = "zoh"


@dataclass(frozen=True)
class Variable:
    """An algebraic variable: ``name = equation`` [unit]."""

    name: str
    equation: str
    unit: str = ""
    description: str = ""


@dataclass(frozen=True)
class State:
    """A state: ``d(name)/dt = derivative``, starting at ``initial`` [unit]."""

    name: str
    derivative: str
    unit: str = ""
    initial: float = 0.0
    description: str = ""


@dataclass(frozen=True)
class Sensor:
    """A measured signal: record column ``name`` = ``measures`` + noise.

    ``noise`` is the standard deviation of the measurement noise [unit];
    ``range`` the sensor's span [unit].
    """

    name: str
    measures: str
    noise: float
    unit: str = ""
    range: tuple[float, float] = (-math.inf, math.inf)
    description: str = ""


@dataclass(frozen=True)
class InputStep:
    """A known change of an input at ``at`` [s]: to ``factor`` x nominal or to ``value``."""

    input: str
    at: float
    factor: float | None = None
    value: float | None = None


@dataclass(frozen=True)
class BuiltInTest:
    """The built-in test: ``duration`` [s] at ``sample_rate`` [Hz], known input steps
    and the excitation added to the inputs (:mod:`condmon.models.excitation`)."""

    duration: float
    sample_rate: float
    schedule: tuple[InputStep, ...] = ()
    excitation: tuple[Excitation, ...] = ()


@dataclass(frozen=True)
class PlantModel:
    """A declared plant model (immutable; see
    :func:`condmon.models.registry.load_plant_model`).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> m = load_plant_model("hst")
    >>> m.state_names, m.sensor_names
    (('Ps', 'Pm', 'omega_m'), ('Ps', 'omega_m'))
    >>> m.fault_candidates
    ('Dp', 'Rlkgp', 'Dm', 'Rlkgm', 'Rv', 'Tld')
    """

    name: str
    description: str
    parameters: tuple[Parameter, ...]
    inputs: tuple[Input, ...]
    variables: tuple[Variable, ...]
    states: tuple[State, ...]
    sensors: tuple[Sensor, ...]
    test: BuiltInTest
    source: str = ""
    smoothing: float | None = None

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.states)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(u.name for u in self.inputs)

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    @property
    def fault_candidates(self) -> tuple[str, ...]:
        """Parameters marked ``fault = true``, in declaration order."""
        return tuple(p.name for p in self.parameters if p.fault)

    def parameter_values(self) -> dict[str, float]:
        """Nominal value of every parameter [SI]."""
        return {p.name: p.value for p in self.parameters}

    def parameter_units(self) -> dict[str, str]:
        """Unit of every parameter, as declared (``"-"``: dimensionless)."""
        return {p.name: p.unit for p in self.parameters}

    def parameter(self, name: str) -> Parameter:
        """The parameter ``name``; :class:`ConfigError` naming the allowed ones."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise ConfigError(f"model {self.name!r} has no parameter {name!r}; "
                          f"allowed: {', '.join(self.parameter_names)}")

    def input_nominal(self, name: str, params: Mapping[str, float] | None = None) -> float:
        """Nominal value of input ``name`` [unit]."""
        u = next(u for u in self.inputs if u.name == name)
        if isinstance(u.nominal, str):
            return float((params or self.parameter_values())[u.nominal])
        return float(u.nominal)

    def with_parameters(self, values: Mapping[str, float], source: str = "") -> PlantModel:
        """A copy with new nominal values for some parameters."""
        for k in values:
            self.parameter(k)
        params = tuple(dataclasses.replace(p, value=float(values[p.name]))
                       if p.name in values else p for p in self.parameters)
        return _validated(dataclasses.replace(self, parameters=params), source or self.source)

    def compile(self) -> CompiledModel:
        """Numerical functions of the model (cached per declaration)."""
        return _compile(self)


def _stacked(values: Sequence[Any], shape: tuple[int, ...]) -> FloatArray:
    """Expressions' values (arrays, or scalars where an expression holds no
    state) as one (len(values), *shape) array: assignment broadcasts a scalar
    for free, where ``np.broadcast_to`` per value took half the time of a
    live stepper's step."""
    out = np.empty((len(values), *shape), dtype=np.float64)
    for i, v in enumerate(values):
        out[i] = v
    return out


@dataclass(frozen=True)
class CompiledModel:
    """Numerical form of a :class:`PlantModel`.

    Attributes
    ----------
    model : PlantModel
    rhs : callable
        ``rhs(x, u, p) -> dx/dt`` with states ``x``, inputs ``u`` and parameters
        ``p`` as arrays in declaration order.
    outputs : callable
        ``outputs(x, u, p) -> y``: the noise-free sensor readings.
    variables : callable
        ``variables(x, u, p) -> v``: the algebraic variables.
    """

    model: PlantModel
    rhs: Callable[[FloatArray, FloatArray, FloatArray], FloatArray]
    outputs: Callable[[FloatArray, FloatArray, FloatArray], FloatArray]
    variables: Callable[[FloatArray, FloatArray, FloatArray], FloatArray]
    _outputs_raw: Callable[..., Any] = dataclasses.field(repr=False, compare=False,
                                                          default=lambda x, u, p: [])
    _variables_raw: Callable[..., Any] = dataclasses.field(repr=False, compare=False,
                                                            default=lambda x, u, p: [])
    _rhs_raw: Callable[..., Any] = dataclasses.field(repr=False, compare=False,
                                                      default=lambda x, u, p: [])

    def rhs_batch(self, x: FloatArray, u: FloatArray, p: FloatArray) -> FloatArray:
        """Derivatives of many copies at once: ``x`` (n_states, N), ``u``
        (n_inputs, N), ``p`` (n_params,) shared or (n_params, N) each copy's;
        returns (n_states, N)."""
        return _stacked(self._rhs_raw(x, u, p), x.shape[1:])

    def outputs_batch(self, x: FloatArray, u: FloatArray, p: FloatArray) -> FloatArray:
        """Sensor readings of many copies: shapes as :meth:`rhs_batch`, (n_sensors, N)."""
        return _stacked(self._outputs_raw(x, u, p), x.shape[1:])

    def outputs_on(self, x: FloatArray, u: FloatArray, p: FloatArray) -> FloatArray:
        """Sensor readings for many samples: ``x`` (n, n_states), ``u`` (n, n_inputs)."""
        return self._vectorised(self._outputs_raw, x, u, p)

    def variables_on(self, x: FloatArray, u: FloatArray, p: FloatArray) -> FloatArray:
        """Algebraic variables for many samples, shape (n, n_variables)."""
        return self._vectorised(self._variables_raw, x, u, p)

    @staticmethod
    def _vectorised(fn: Callable[..., Any], x: FloatArray, u: FloatArray, p: FloatArray
                    ) -> FloatArray:
        vals = fn(x.T, u.T, p)
        return np.column_stack([np.broadcast_to(np.asarray(v, dtype=np.float64), (len(x),))
                                for v in vals]) if len(vals) else np.empty((len(x), 0))

    def parameter_vector(self, values: Mapping[str, float] | None = None) -> FloatArray:
        """Nominal parameters with ``values`` overriding some, as an array."""
        base = self.model.parameter_values()
        if values:
            base.update(values)
        return np.array([base[n] for n in self.model.parameter_names], dtype=np.float64)


def symbols_of(model: PlantModel) -> dict[str, sp.Symbol]:
    """One real sympy symbol per declared name."""
    import sympy as sp

    names = (*model.parameter_names, *model.input_names,
             *(v.name for v in model.variables), *model.state_names)
    return {n: sp.Symbol(n, real=True) for n in names}


@functools.lru_cache(maxsize=32)
def equations_of(model: PlantModel) -> tuple[dict[str, sp.Expr], dict[str, sp.Expr],
                                             dict[str, sp.Expr]]:
    """Parsed equations: (variables, state derivatives, sensor readings), as written."""
    from condmon.models.expressions import parse_expression

    sym = symbols_of(model)
    allowed_v = {k: s for k, s in sym.items()}
    variables: dict[str, sp.Expr] = {}
    for i, v in enumerate(model.variables):  # a variable may use the ones before it
        later = {w.name for w in model.variables[i:]}
        allowed = {k: s for k, s in allowed_v.items() if k not in later}
        variables[v.name] = parse_expression(v.equation, allowed,
                                             f"{model.source}[variables.{v.name}]")
    derivs = {s.name: parse_expression(s.derivative, sym, f"{model.source}[states.{s.name}]")
              for s in model.states}
    readings = {s.name: parse_expression(s.measures, sym, f"{model.source}[sensors.{s.name}]")
                for s in model.sensors}
    return variables, derivs, readings


@functools.lru_cache(maxsize=32)
def substituted_equations(model: PlantModel) -> tuple[dict[str, sp.Expr], dict[str, sp.Expr],
                                                      dict[str, sp.Expr]]:
    """Equations over states, inputs and parameters only: the algebraic
    variables substituted in. (variables, state derivatives, sensor readings)."""
    variables, derivs, readings = equations_of(model)
    sym = symbols_of(model)
    resolved: dict[sp.Symbol, sp.Expr] = {}
    for name, expr in variables.items():
        resolved[sym[name]] = expr.xreplace(resolved)
    return ({v: resolved[sym[v]] for v in variables},
            {k: e.xreplace(resolved) for k, e in derivs.items()},
            {k: e.xreplace(resolved) for k, e in readings.items()})


def smoothing_width(model: PlantModel) -> float:
    """The width ``model`` smooths ``sign``, ``abs``, ``min`` and ``max`` over:
    its ``[smoothing] eps``, else the ``[simulation]`` default. [argument units]

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> smoothing_width(load_plant_model("dc-motor"))
    1e-06
    """
    return model.smoothing if model.smoothing is not None else \
        float(load_default("isolation.toml")["simulation"]["smoothing_eps"])


@functools.lru_cache(maxsize=32)
def _compile(model: PlantModel) -> CompiledModel:
    eps = smoothing_width(model)
    rhs, outputs, variables = derived_cache.cached(
        derived_cache.plant_key(model), f"compiled:{eps!r}",
        lambda: _lambdified(model, eps), lambda fns: _dump_compiled(model, fns),
        lambda data: tuple(derived_cache.restore_function(data[k])
                           for k in ("rhs", "outputs", "variables")))

    def make(fn: Callable[..., Any]) -> Callable[[FloatArray, FloatArray, FloatArray], FloatArray]:
        def call(x: FloatArray, u: FloatArray, p: FloatArray) -> FloatArray:
            return np.array(fn(x, u, p), dtype=np.float64)
        return call

    return CompiledModel(model, make(rhs), make(outputs), make(variables), outputs, variables,
                         rhs)


def _lambdified(model: PlantModel, eps: float) -> tuple[Callable[..., Any], ...]:
    """The model's right-hand side, sensor readings and variables as numpy
    functions of (states, inputs, parameters), the non-smooth functions smoothed."""
    import sympy as sp

    from condmon.models.expressions import smoothed

    sym = symbols_of(model)
    xs = [sym[n] for n in model.state_names]
    us = [sym[n] for n in model.input_names]
    ps = [sym[n] for n in model.parameter_names]
    var_exprs, deriv_exprs, out_exprs = ([smoothed(e, eps) for e in d.values()]
                                         for d in substituted_equations(model))

    def raw(exprs: list[sp.Expr]) -> Callable[..., Any]:
        return sp.lambdify((xs, us, ps), exprs, modules="numpy", cse=True)  # type: ignore[no-any-return]

    return raw(deriv_exprs), raw(out_exprs), raw(var_exprs)


def _dump_compiled(model: PlantModel, fns: tuple[Callable[..., Any], ...]
                   ) -> dict[str, Any] | None:
    probe = ([s.initial + 0.5 for s in model.states],
             [model.input_nominal(u.name) for u in model.inputs],
             [p.value for p in model.parameters])
    kept = [derived_cache.portable(fn, *probe) for fn in fns]
    if any(k is None for k in kept):
        return None
    return dict(zip(("rhs", "outputs", "variables"), kept))


# -- loading and validation ------------------------------------------------------------


#: Top-level entries a declaration may hold.
DECLARATION_KEYS = ("name", "description", "parameters", "inputs", "variables", "states",
                    "sensors", "test", "smoothing", "estimation", "monitor", "record", "regimes",
                    "features", "conditions")


def plant_from_doc(doc: Mapping[str, Any], source: str) -> PlantModel:
    """Read and validate a declaration already parsed from TOML (``source`` names it)."""
    unknown = [k for k in doc if k not in DECLARATION_KEYS]
    if unknown:
        raise ConfigError(f"{source}: unknown entry {unknown[0]!r}; a declaration holds "
                          f"{', '.join(DECLARATION_KEYS)}")
    return _validated(_from_doc(doc, source), source)


def _table(doc: Mapping[str, Any], key: str, source: str) -> dict[str, Any]:
    value = doc.get(key, {})
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: [{key}] must be a table")
    return value


#: How a record's samples of an input act between sample times (:class:`Input`).
INTERSAMPLE = {"zoh": "held over each sample", "bl": "the values at the sample times"}


def _fields(entry: Any, where: str, required: tuple[str, ...], optional: tuple[str, ...]
            ) -> dict[str, Any]:
    if not isinstance(entry, dict):
        raise ConfigError(f"{where} must be a table with {', '.join(required)}")
    unknown = set(entry) - set(required) - set(optional)
    if unknown:
        raise ConfigError(f"{where}: unknown key {sorted(unknown)[0]!r}; "
                          f"allowed: {', '.join((*required, *optional))}")
    missing = [k for k in required if k not in entry]
    if missing:
        raise ConfigError(f"{where}: missing {missing[0]!r}")
    return entry


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where} must be a finite number, not {value!r}")
    return float(value)


def _from_doc(doc: Mapping[str, Any], src: str) -> PlantModel:
    text = ("unit", "description")
    params = []
    for k, e in _table(doc, "parameters", src).items():
        f = _fields(e, f"{src}[parameters.{k}]", ("value",), (*text, "fault", "range"))
        value = _number(f["value"], f"{src}[parameters.{k}].value")
        rng = _range(f, f"{src}[parameters.{k}].range") if "range" in f else None
        params.append(Parameter(k, value, f.get("unit", ""), f.get("description", ""),
                                bool(f.get("fault", False)), rng))
    inputs = []
    for k, e in _table(doc, "inputs", src).items():
        f = _fields(e, f"{src}[inputs.{k}]", ("nominal",), (*text, "range", "intersample"))
        nominal = f["nominal"] if isinstance(f["nominal"], str) else \
            _number(f["nominal"], f"{src}[inputs.{k}].nominal")
        hold = f.get("intersample", "zoh")
        if hold not in INTERSAMPLE:
            raise ConfigError(f"{src}[inputs.{k}].intersample: {hold!r}; allowed: "
                              + ", ".join(f"{v!r} ({what})" for v, what in INTERSAMPLE.items()))
        inputs.append(Input(k, nominal, f.get("unit", ""), f.get("description", ""),
                            _range(f, f"{src}[inputs.{k}].range") if "range" in f
                            else (-math.inf, math.inf), hold))
    variables = [Variable(k, str(_fields(e, f"{src}[variables.{k}]", ("equation",), text)["equation"]),
                          e.get("unit", ""), e.get("description", ""))
                 for k, e in _table(doc, "variables", src).items()]
    states = []
    for k, e in _table(doc, "states", src).items():
        f = _fields(e, f"{src}[states.{k}]", ("derivative",), (*text, "initial"))
        states.append(State(k, str(f["derivative"]), f.get("unit", ""),
                            _number(f.get("initial", 0.0), f"{src}[states.{k}].initial"),
                            f.get("description", "")))
    sensors = []
    for k, e in _table(doc, "sensors", src).items():
        f = _fields(e, f"{src}[sensors.{k}]", ("measures", "noise"), (*text, "range"))
        sensors.append(Sensor(k, str(f["measures"]), _number(f["noise"], f"{src}[sensors.{k}].noise"),
                              f.get("unit", ""),
                              _range(f, f"{src}[sensors.{k}].range", finite=False)
                              if "range" in f else (-math.inf, math.inf),
                              f.get("description", "")))
    t = _fields(_table(doc, "test", src), f"{src}[test]", ("duration", "sample_rate"),
                ("schedule", "excitation"))
    steps = []
    for i, s in enumerate(t.get("schedule", [])):
        where = f"{src}[test].schedule[{i}]"
        f = _fields(s, where, ("input", "at"), ("factor", "value"))
        if ("factor" in f) == ("value" in f):
            raise ConfigError(f"{where}: give exactly one of 'factor' and 'value'")
        steps.append(InputStep(str(f["input"]), _number(f["at"], f"{where}.at"),
                               _number(f["factor"], where) if "factor" in f else None,
                               _number(f["value"], where) if "value" in f else None))
    fs = _number(t["sample_rate"], f"{src}[test].sample_rate")
    test = BuiltInTest(_number(t["duration"], f"{src}[test].duration"), fs,
                       tuple(sorted(steps, key=lambda s: s.at)),
                       parse_excitation(t.get("excitation", []), f"{src}[test]",
                                        [u.name for u in inputs], fs))
    smooth = _fields(_table(doc, "smoothing", src), f"{src}[smoothing]", (), ("eps",))
    eps = _number(smooth["eps"], f"{src}[smoothing].eps") if "eps" in smooth else None
    if eps is not None and eps < 0:
        raise ConfigError(f"{src}[smoothing].eps must be >= 0 (0: exact), not {eps:g}")
    return PlantModel(str(doc.get("name", Path(src).stem)), str(doc.get("description", "")),
                      tuple(params), tuple(inputs), tuple(variables), tuple(states),
                      tuple(sensors), test, src, eps)


def _range(entry: Mapping[str, Any], where: str, finite: bool = True) -> tuple[float, float]:
    """``range = [low, high]`` of a declaration entry, low < high."""
    rng = entry["range"]
    if not isinstance(rng, list) or len(rng) != 2 or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) for v in rng):
        raise ConfigError(f"{where} must be [low, high] (two numbers)")
    lo, hi = float(rng[0]), float(rng[1])
    if (finite and not (math.isfinite(lo) and math.isfinite(hi))) or not lo < hi:
        raise ConfigError(f"{where} must be [low, high] with low < high, not {rng!r}")
    return lo, hi


def _validated(m: PlantModel, src: str) -> PlantModel:
    m = dataclasses.replace(m, source=src)
    names = [*m.parameter_names, *m.input_names, *(v.name for v in m.variables), *m.state_names]
    seen: set[str] = set()
    for n in names:
        if not _NAME.match(n):
            raise ConfigError(f"{src}: {n!r} is not a valid name (letters, digits, _)")
        if n in seen:
            raise ConfigError(f"{src}: the name {n!r} is declared twice")
        if n.startswith(("d_", "y_")):
            raise ConfigError(f"{src}: names starting with d_ or y_ are reserved ({n!r})")
        seen.add(n)
    if not m.states:
        raise ConfigError(f"{src}: the model declares no [states]")
    if not m.sensors:
        raise ConfigError(f"{src}: the model declares no [sensors]")
    for u in m.inputs:
        if isinstance(u.nominal, str) and u.nominal not in m.parameter_names:
            raise ConfigError(f"{src}[inputs.{u.name}].nominal: unknown parameter {u.nominal!r}; "
                              f"allowed: {', '.join(m.parameter_names)}")
    for p in m.parameters:
        if p.range is not None and not p.range[0] <= p.value <= p.range[1]:
            raise ConfigError(f"{src}[parameters.{p.name}]: value {p.value:g} lies outside its "
                              f"range [{p.range[0]:g}, {p.range[1]:g}]")
    for s in m.sensors:
        if not s.noise > 0:
            raise ConfigError(f"{src}[sensors.{s.name}].noise must be > 0, not {s.noise!r}")
    if not (m.test.duration > 0 and m.test.sample_rate > 0):
        raise ConfigError(f"{src}[test]: duration and sample_rate must be > 0")
    for step in m.test.schedule:
        if step.input not in m.input_names:
            raise ConfigError(f"{src}[test].schedule: unknown input {step.input!r}; "
                              f"allowed: {', '.join(m.input_names) or '(none declared)'}")
    # every equation parses, known names only (checked once per set of equations)
    derived_cache.cached(derived_cache.plant_key(m), "equations", lambda: _check_equations(m, src),
                         lambda ok: ok, lambda data: bool(data))
    return m


def _check_equations(m: PlantModel, src: str) -> bool:
    import sympy as sp

    variables, derivs, readings = equations_of(m)
    for kind, eqs in (("variables", variables), ("states", derivs), ("sensors", readings)):
        for name, expr in eqs.items():
            if expr.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
                raise ConfigError(f"{src}[{kind}.{name}]: the equation is infinite or undefined "
                                  f"as written ({expr}): a division by zero?")
    return True
