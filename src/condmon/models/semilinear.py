"""Semi-linear structure of a declared model: linear in its states, with
nonlinear terms of measured signals as extra inputs.

``dx/dt = A(p) x + B(p) [u, g_1, ..., g_r]`` where each ``g_k`` is a
nonlinear function of inputs and *measured* states (``sign(omega)`` of a
Coulomb friction, a constant 1 for an offset) and the sensors read ``y = C x``.
Derived symbolically from the declaration; used by the output-error route,
which simulates the model with the exact zero-order-hold discretisation of its
linear part and the measured ``g_k`` held over each sample.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import sympy as sp
from numpy.typing import NDArray

from condmon.errors import ModelError
from condmon.models.declared import substituted_equations, symbols_of
from condmon.models.machine import Machine

__all__ = ["SemiLinearStructure", "semilinear_structure"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SemiLinearStructure:
    """Matrices of the semi-linear form as functions of the unknowns.

    Attributes
    ----------
    states : tuple of str
    inputs : tuple of str
        Declared inputs that enter the equations (record columns).
    signal_terms : tuple of sympy.Expr
        The nonlinear input terms ``g_k`` (functions of inputs and measured
        states; a constant term is ``1``).
    sensors : tuple of str
        Record columns of the sensors, in the rows of ``C``.
    matrices : callable
        ``matrices(unknowns, constants) -> (A, B, C)`` with ``B`` over
        ``[inputs..., g_1...]``.
    measured : dict of str to str
        ``state -> sensor column`` of each measured state.
    """

    states: tuple[str, ...]
    inputs: tuple[str, ...]
    signal_terms: tuple[sp.Expr, ...]
    sensors: tuple[str, ...]
    matrices: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray, FloatArray]]
    measured: dict[str, str]


def _linear_coefficient(term: sp.Expr, syms: list[sp.Symbol]) -> tuple[sp.Symbol, sp.Expr] | None:
    """``(s, c)`` when ``term = c * s`` with ``s`` one of ``syms`` and ``c`` free of them."""
    present = [s for s in syms if term.has(s)]
    if len(present) != 1 or term.has(sp.sign, sp.Abs, sp.Min, sp.Max):
        return None
    s = present[0]
    c = sp.simplify(term / s)
    return (s, c) if not c.has(*syms) else None


@functools.lru_cache(maxsize=32)
def semilinear_structure(machine: Machine) -> SemiLinearStructure:
    """Derive the semi-linear form; :class:`ModelError` with the reason if none exists.

    Example
    -------
    >>> from condmon.models import get_model
    >>> s = semilinear_structure(get_model("dc-motor"))
    >>> s.inputs, s.signal_terms
    (('V',), ())
    """
    plant = machine.plant
    sym = symbols_of(plant)
    _, derivs, readings = substituted_equations(plant)
    where = f"{plant.source}: the output-error route"
    xs = [sym[n] for n in plant.state_names]
    us = [sym[n] for n in plant.input_names]
    measured = {str(e): name for name, e in readings.items() if isinstance(e, sp.Symbol)}
    for name, e in readings.items():
        if not isinstance(e, sp.Symbol) or str(e) not in plant.state_names:
            raise ModelError(f"{where}: sensor {name!r} must read one state, not {e}")
    signals: list[sp.Expr] = []
    a_rows: list[dict[str, sp.Expr]] = []
    b_rows: list[dict[str, sp.Expr]] = []
    for name in plant.state_names:
        a_row: dict[str, sp.Expr] = {}
        b_row: dict[str, sp.Expr] = {}
        for term in sp.Add.make_args(sp.expand(derivs[name])):
            lin = _linear_coefficient(term, [*xs, *us])
            if lin is not None:
                target = a_row if lin[0] in xs else b_row
                target[str(lin[0])] = target.get(str(lin[0]), sp.Integer(0)) + lin[1]
                continue
            coeff, g = term.as_independent(*xs, *us, as_Add=False)
            bad = {str(s) for s in g.free_symbols if s in xs} - set(measured)
            if bad:
                raise ModelError(f"{where}: the term {term} of d{name}/dt is nonlinear in "
                                 f"{', '.join(sorted(bad))}, which no sensor measures")
            if g not in signals:
                signals.append(g)
            key = f"g{signals.index(g)}"
            b_row[key] = b_row.get(key, sp.Integer(0)) + coeff
        a_rows.append(a_row)
        b_rows.append(b_row)
    used_inputs = [u for u in plant.input_names if any(u in r for r in b_rows)]
    cols = [*used_inputs, *(f"g{k}" for k in range(len(signals)))]
    A = sp.Matrix([[r.get(x, 0) for x in plant.state_names] for r in a_rows])
    B = sp.Matrix([[r.get(c, 0) for c in cols] for r in b_rows])
    C = sp.Matrix([[1 if str(readings[s]) == x else 0 for x in plant.state_names]
                   for s in plant.sensor_names])
    unknowns = [sym[k] for k in machine.spec.unknowns]
    known = [sym[p] for p in plant.parameter_names if p not in machine.spec.unknowns]
    f_a = sp.lambdify((unknowns, known), A.tolist(), modules="numpy")
    f_b = sp.lambdify((unknowns, known), B.tolist(), modules="numpy")
    c_num = np.array(C.tolist(), dtype=np.float64)

    def matrices(p: FloatArray, k: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        a = np.array(f_a(list(p), list(k)), dtype=np.float64).reshape(A.shape)
        b = np.array(f_b(list(p), list(k)), dtype=np.float64).reshape(B.shape)
        return a, b, c_num

    return SemiLinearStructure(plant.state_names, tuple(used_inputs), tuple(signals),
                               plant.sensor_names, matrices, measured)
