"""How the simulation-error route treats initial states, segments and starts.

A declaration's ``[estimation]`` table may hold, for the simulation-error
route (:mod:`condmon.identify.simulation_route`)::

    segments = 1          # multiple shooting: the record cut in this many segments
    starts = 4            # optimiser starts (the declared values, then draws)

    [estimation.initial]  # per state; default "estimate"
    x1 = { ge = 0.0, le = 12.0 }   # estimated, within these bounds [state unit]
    x2 = "first-sample"            # the sensor's first reading (a state a sensor reads)
    x3 = "declared"                # the declared initial value, not estimated

As MATLAB's ``nlgreyest`` does (``InitialStates``: estimate, fixed, or zero),
an initial state is an unknown of its own by default, and is reported with
its standard error.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from condmon.errors import ConfigError

if TYPE_CHECKING:
    from condmon.models.declared import PlantModel

__all__ = ["InitialState", "SimulationSettings", "parse_simulation_settings", "INITIAL_MODES",
           "state_readers"]

#: How an initial state may be set.
INITIAL_MODES = ("estimate", "first-sample", "declared")
_MAX_SEGMENTS = 500
_MAX_STARTS = 50


@dataclass(frozen=True)
class InitialState:
    """One state's initial value: ``mode`` one of :data:`INITIAL_MODES`; an
    estimated one stays within ``[low, high]``. [state unit]"""

    mode: str = "estimate"
    low: float = -math.inf
    high: float = math.inf


@dataclass(frozen=True)
class SimulationSettings:
    """The simulation-error route's settings (``segments``, ``starts`` and
    ``[estimation.initial]``); a state not named is estimated, unbounded."""

    initial: dict[str, InitialState] = field(default_factory=dict)
    segments: int = 1
    starts: int = 4

    def of(self, state: str) -> InitialState:
        """The setting of one state."""
        return self.initial.get(state, InitialState())


def _count(value: Any, where: str, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= high:
        raise ConfigError(f"{where} must be an integer from 1 to {high}, got {value!r}")
    return value


def parse_simulation_settings(est: Mapping[str, Any], states: tuple[str, ...],
                              sensed: Callable[[], set[str]], src: str) -> SimulationSettings:
    """Read ``segments``, ``starts`` and ``[estimation.initial]``.

    Parameters
    ----------
    est : mapping
        The ``[estimation]`` table.
    states : tuple of str
        The declared states.
    sensed : callable
        Gives the states a sensor's reading gives back (:func:`state_readers`):
        only these may start from their first sample (asked only then).
    src : str
        The declaration, named in errors.

    Raises
    ------
    ConfigError
        Naming the key and the allowed values.

    Example
    -------
    >>> s = parse_simulation_settings({"initial": {"x1": {"ge": 0.0}}}, ("x1", "x2"),
    ...                               lambda: {"x2"}, "t")
    >>> s.of("x1"), s.of("x2").mode
    (InitialState(mode='estimate', low=0.0, high=inf), 'estimate')
    """
    where = f"{src}[estimation]"
    segments = _count(est.get("segments", 1), f"{where}.segments", _MAX_SEGMENTS)
    starts = _count(est.get("starts", 4), f"{where}.starts", _MAX_STARTS)
    table = est.get("initial", {})
    if not isinstance(table, dict):
        raise ConfigError(f"{where}.initial must be a table of states")
    out: dict[str, InitialState] = {}
    for name, entry in table.items():
        w = f"{src}[estimation.initial.{name}]"
        if name not in states:
            raise ConfigError(f"{w}: {name!r} is not a state of the model; allowed: "
                              f"{', '.join(states)}")
        if isinstance(entry, str):
            # "estimated" and "first sample" read as a user writes them
            entry = {"estimated": "estimate", "first sample": "first-sample"}.get(entry.strip(),
                                                                             entry.strip())
            if entry not in INITIAL_MODES:
                raise ConfigError(f"{w}: unknown setting {entry!r}; allowed: "
                                  f"{', '.join(INITIAL_MODES)}, or a table of bounds "
                                  "{ ge = ..., le = ... }")
            if entry == "first-sample" and name not in sensed():
                raise ConfigError(f"{w}: 'first-sample' needs a sensor whose reading gives "
                                  f"{name!r} back; no sensor's does")
            out[name] = InitialState(entry)
            continue
        if not isinstance(entry, dict) or set(entry) - {"ge", "gt", "le", "lt"}:
            raise ConfigError(f"{w} must be one of {', '.join(INITIAL_MODES)} or a table of "
                              "bounds with keys ge/gt, le/lt")
        vals = {}
        for k, v in entry.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"{w}.{k} must be a finite number, got {v!r}")
            vals[k] = float(v)
        low = vals.get("ge", vals.get("gt", -math.inf))
        high = vals.get("le", vals.get("lt", math.inf))
        if not low < high:
            raise ConfigError(f"{w}: the lower bound {low:g} is not below the upper {high:g}")
        out[name] = InitialState("estimate", low, high)
    return SimulationSettings(out, segments, starts)


def state_readers(plant: PlantModel) -> dict[str, tuple[int, Callable[..., Any]]]:
    """States a sensor's reading gives back: ``state -> (sensor index,
    fn(reading, parameter vector) -> state value)``.

    A sensor reads a state when its equation holds that one state and no
    other, and sympy solves it for the state in one way (``x2 + y0``: yes;
    ``x**2``: two ways, no). [state units]

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> readers = state_readers(load_plant_model("dc-motor"))
    >>> sorted(readers)
    ['I', 'omega']
    """
    return _readers(plant)


@functools.lru_cache(maxsize=32)
def _readers(plant: PlantModel) -> dict[str, tuple[int, Callable[..., Any]]]:
    import sympy as sp

    from condmon.models.declared import substituted_equations, symbols_of

    sym = symbols_of(plant)
    states = {sym[n]: n for n in plant.state_names}
    params = [sym[n] for n in plant.parameter_names]
    reading = sp.Symbol("_reading", real=True)
    out: dict[str, tuple[int, Callable[..., Any]]] = {}
    for j, (_, expr) in enumerate(substituted_equations(plant)[2].items()):
        held = [s for s in expr.free_symbols if s in states]
        if len(held) != 1 or any(s.name in plant.input_names for s in expr.free_symbols):
            continue
        x = held[0]
        try:
            sol = sp.solve(sp.Eq(expr, reading), x)
        except (NotImplementedError, ValueError, TypeError):
            continue
        if len(sol) == 1 and states[x] not in out:
            out[states[x]] = (j, sp.lambdify((reading, params), sol[0], modules="numpy"))
    return out
