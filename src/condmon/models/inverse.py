"""The inverse-model structure of a declared machine: its equations linear in the unknowns.

Each state equation ``den·x' - num = 0`` holding an unknown is written as
``Σ θ_k φ_k(signals) = known(signals)`` (derived symbolically with sympy), for
the inverse-model and steady routes (:mod:`condmon.identify.inverse_route`,
:mod:`condmon.identify.steady_route`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

from condmon.errors import ModelError
from condmon.models.declared import substituted_equations, symbols_of

if TYPE_CHECKING:
    import sympy as sp

    from condmon.models.machine import Machine

__all__ = ["InverseEquation", "InverseStructure", "inverse_structure"]


@dataclass(frozen=True)
class InverseEquation:
    """One state equation in linear-in-the-parameters form.

    ``Σ_k θ_k φ_k = known`` with ``θ`` the unknowns in ``terms`` (several terms
    may share one unknown through known factors).

    Attributes
    ----------
    state : str
        The state whose derivative the equation gives.
    terms : tuple of (str, sympy.Expr)
        ``(unknown, regressor)``: the regressor is an expression of signals
        (states, their derivatives ``d_<state>``, inputs) and known constants.
    known : sympy.Expr
        Right-hand side: signals and constants only.
    """

    state: str
    terms: tuple[tuple[str, sp.Expr], ...]
    known: sp.Expr


@dataclass(frozen=True)
class InverseStructure:
    """Linear-in-the-parameters form of the state equations that carry unknowns.

    Attributes
    ----------
    equations : tuple of InverseEquation
    signals : tuple of str
        States needed as signals (measured by a sensor or derived by
        differentiating a measured state), in order of derivation.
    derivation : dict of str to str
        ``state -> measured state it is the derivative of`` for derived states.
    columns : tuple of str
        Record columns the equations need: inputs, then sensors.
    """

    equations: tuple[InverseEquation, ...]
    signals: tuple[str, ...]
    derivation: dict[str, str]
    columns: tuple[str, ...] = ()


@functools.lru_cache(maxsize=32)
def inverse_structure(machine: Machine) -> InverseStructure:
    """The machine's inverse structure (see :meth:`condmon.models.Machine.inverse`).

    Raises
    ------
    ModelError
        An equation not linear in the unknowns, or needing a signal neither
        measured nor the derivative of a measured state.
    """
    import sympy as sp

    plant, spec = machine.plant, machine.spec
    sym = symbols_of(plant)
    _, derivs, readings = substituted_equations(plant)
    where = f"{plant.source}: the inverse-model route"
    measured = {str(e) for e in readings.values() if isinstance(e, sp.Symbol)}
    derivation: dict[str, str] = {}
    for name, e in derivs.items():  # x' = y with y a state: y = dx/dt
        if isinstance(e, sp.Symbol) and str(e) in plant.state_names and name in measured:
            derivation[str(e)] = name
    unknown_syms = {sym[k] for k in spec.unknowns}
    equations = []
    for name, e in derivs.items():
        if not e.free_symbols & unknown_syms:
            continue
        dx = sp.Symbol(f"d_{name}", real=True)
        num, den = sp.fraction(sp.together(e))
        resid = sp.expand(den * dx - num)  # = 0
        terms: dict[str, sp.Expr] = {}
        known = sp.Integer(0)
        for term in sp.Add.make_args(resid):
            ps = term.free_symbols & unknown_syms
            if len(ps) > 1 or (ps and not _linear_in(term, next(iter(ps)))):
                raise ModelError(f"{where}: d{name}/dt = {e} is not linear in the unknowns "
                                 f"(term {term})")
            if not ps:
                known -= term
                continue
            p = next(iter(ps))
            terms[str(p)] = terms.get(str(p), sp.Integer(0)) + term / p
        equations.append(InverseEquation(name, tuple(terms.items()), sp.simplify(known)))
    if not equations:
        raise ModelError(f"{where}: no state equation holds an unknown parameter")
    available = measured | set(derivation)
    used: set[str] = set()
    for eq in equations:
        need = set()
        for _, phi in eq.terms:
            need |= {str(s) for s in phi.free_symbols}
        need |= {str(s) for s in eq.known.free_symbols}
        used |= need
        states_needed = {s for s in need if s in plant.state_names}
        d_needed = {s[2:] for s in need if s.startswith("d_")}
        missing = sorted((states_needed | d_needed) - available)
        if missing:
            raise ModelError(f"{where}: the equation of {eq.state!r} needs "
                             f"{', '.join(missing)}, neither measured nor the derivative "
                             "of a measured state")
    covered = {p for eq in equations for p, _ in eq.terms}
    if set(spec.unknowns) - covered:
        raise ModelError(f"{where}: {', '.join(sorted(set(spec.unknowns) - covered))} "
                         "appear in no usable equation")
    signals = tuple(s for s in plant.state_names if s in available)
    columns = (*(u for u in plant.input_names if u in used),
               *(name for name, e in readings.items() if str(e) in signals))
    return InverseStructure(tuple(equations), signals, derivation, columns)


def _linear_in(term: sp.Expr, p: sp.Symbol) -> bool:
    """Whether ``term`` is ``p`` times something free of ``p`` (an unknown inside
    ``max``, ``sqrt`` or ``sign`` is not)."""
    import sympy as sp

    try:
        return bool(sp.degree(term, p) == 1) and not sp.diff(term, p).has(p)
    except sp.PolynomialError:
        return False
