"""Structural analysis of a declared model: residual generators and the fault
signature matrix (FSM), derived from the equations, not typed in.

The equations of a :class:`~condmon.models.declared.PlantModel` are handed to the
Fault Diagnosis Toolbox (``faultdiagnosistoolbox``) in residual form: one
relation per algebraic variable, per state derivative, a differential constraint
per state, and one measurement relation per sensor; the candidate faults are the
parameters marked ``fault = true``. From its minimal structurally overdetermined
(MSO) sets condmon takes the residual generators:

- ``"simulation"`` (the reference method): one residual per sensor, the model run
  from the known inputs alone beside the plant; its equations are the MSO made of
  the whole model and that one sensor.
- ``"structured"``: every MSO of the model with all sensors that can be computed
  by integration alone (integral causality), the other sensors of the set used as
  inputs. More sensors give more such residuals and so finer isolation.

Note: the toolbox's isolability matrices hold 1 where a fault is *not* isolable
from another (despite its docstring); this module turns them into booleans that
say "isolable".
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError, ModelError
from condmon.models import derived_cache
from condmon.models.declared import (
    PlantModel, equations_of, substituted_equations, symbols_of,
)

if TYPE_CHECKING:
    import sympy as sp

# The analysis (sympy, the toolbox with scikit-learn and matplotlib) runs once
# per set of equations: its results are kept in condmon.models.derived_cache.

__all__ = ["ResidualGenerator", "FaultSignature", "RESIDUAL_KINDS", "residual_generators",
           "fault_signature", "suspects"]

RESIDUAL_KINDS = ("simulation", "structured")
ResidualKind = Literal["simulation", "structured"]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class ResidualGenerator:
    """One residual: sensor ``sensor`` minus the model's prediction of it.

    Attributes
    ----------
    name : str
        ``r_<sensor>``, or ``r_<sensor>|<input sensors>`` for a structured one.
    sensor : str
        The sensor compared with the prediction.
    integrated : tuple of str
        States integrated to predict it.
    inputs : tuple of str
        Sensors whose measurements stand in for states (structured residuals).
    equations : tuple of str
        Labels of the model relations used.
    faults : tuple of str
        Candidate faults the residual is structurally sensitive to.
    """

    name: str
    sensor: str
    integrated: tuple[str, ...]
    inputs: tuple[str, ...]
    equations: tuple[str, ...]
    faults: tuple[str, ...]


@dataclass(frozen=True)
class FaultSignature:
    """Fault signature matrix and isolability of a residual set.

    Attributes
    ----------
    faults : tuple of str
        Candidate faults (rows).
    residuals : tuple of str
        Residual names (columns).
    matrix : ndarray of int, shape (n_faults, n_residuals)
        1 where the residual is structurally sensitive to the fault.
    isolable : ndarray of bool, shape (n_faults, n_faults)
        ``isolable[i, j]``: fault i can be told from fault j with these residuals.
    model_isolable : ndarray of bool, shape (n_faults, n_faults)
        The same for the model itself (any residual, integral causality).
    """

    faults: tuple[str, ...]
    residuals: tuple[str, ...]
    matrix: IntArray
    isolable: NDArray[np.bool_]
    model_isolable: NDArray[np.bool_]

    @property
    def mb(self) -> dict[str, int]:
        """Monitorable: 1 when the fault moves at least one residual."""
        return {f: int(self.matrix[i].any()) for i, f in enumerate(self.faults)}

    @property
    def ib(self) -> dict[str, int]:
        """Isolable: 1 when monitorable and its signature differs from every other."""
        out = {}
        for i, f in enumerate(self.faults):
            others = np.delete(self.isolable[i], i)
            out[f] = int(self.matrix[i].any() and bool(others.all()))
        return out

    def signature(self, fault: str) -> tuple[int, ...]:
        """The fault's row of the FSM."""
        return tuple(int(v) for v in self.matrix[self.faults.index(fault)])

    def to_dict(self) -> dict[str, Any]:
        """``{"residuals": [...], "rows": {fault: {"signature", "Mb", "Ib"}}}``."""
        mb, ib = self.mb, self.ib
        return {"residuals": list(self.residuals),
                "rows": {f: {"signature": list(self.signature(f)), "Mb": mb[f], "Ib": ib[f]}
                         for f in self.faults}}

    def table(self) -> str:
        """Plain-text table of the FSM with Mb and Ib."""
        head = ["fault", *self.residuals, "Mb", "Ib"]
        rows = [[f, *(str(v) for v in self.signature(f)), str(self.mb[f]), str(self.ib[f])]
                for f in self.faults]
        widths = [max(len(r[k]) for r in [head, *rows]) for k in range(len(head))]
        return "\n".join("  ".join(c.rjust(w) if k else c.ljust(w)
                                   for k, (c, w) in enumerate(zip(r, widths)))
                         for r in [head, *rows])


@dataclass(frozen=True)
class _Relations:
    labels: tuple[str, ...]
    rels: tuple[Any, ...]
    unknowns: tuple[str, ...]
    known: tuple[str, ...]
    faults: tuple[str, ...]
    others: tuple[str, ...]


def _relations(model: PlantModel) -> _Relations:
    import sympy as sp

    variables, derivs, readings = equations_of(model)
    sym = symbols_of(model)
    labels: list[str] = []
    rels: list[Any] = []
    for v, expr in variables.items():
        labels.append(f"var:{v}")
        rels.append(-sym[v] + expr)
    for s, expr in derivs.items():
        labels.append(f"der:{s}")
        rels.append(-sp.Symbol(f"d_{s}", real=True) + expr)
    for s in derivs:
        labels.append(f"diff:{s}")
        rels.append([f"d_{s}", s, "diff"])
    for s, expr in readings.items():
        labels.append(f"sensor:{s}")
        rels.append(-sp.Symbol(f"y_{s}", real=True) + expr)
    unknowns = (*variables, *model.state_names, *(f"d_{s}" for s in model.state_names))
    known = (*(f"y_{s}" for s in model.sensor_names), *model.input_names)
    faults = model.fault_candidates
    others = tuple(p for p in model.parameter_names if p not in faults)
    return _Relations(tuple(labels), tuple(rels), unknowns, known, faults, others)


def _fdt_model(r: _Relations, keep: Sequence[int]) -> Any:
    import faultdiagnosistoolbox as fdt  # heavy import (scikit-learn): only when analysing

    # The toolbox prints (does not raise) on problems it sees; condmon validates first.
    return fdt.DiagnosisModel({"type": "Symbolic", "x": list(r.unknowns), "f": list(r.faults),
                               "z": list(r.known), "parameters": list(r.others),
                               "rels": [r.rels[i] for i in keep]})


def _states_in(expr: sp.Expr, model: PlantModel) -> set[str]:
    names = set(model.state_names)
    return {str(s) for s in expr.free_symbols if str(s) in names}


def _generator(model: PlantModel, r: _Relations, eqs: Iterable[int]) -> ResidualGenerator | None:
    """The residual generator computing an equation set by integration, or None."""
    import sympy as sp

    labels = [r.labels[i] for i in sorted(eqs)]
    integrated = [lab[4:] for lab in labels if lab.startswith("der:")]
    sensors = [lab[7:] for lab in labels if lab.startswith("sensor:")]
    readings = equations_of(model)[2]
    _, flat_derivs, flat_readings = substituted_equations(model)
    compared, inputs = [], []
    for s in sensors:
        reading = readings[s]
        if isinstance(reading, sp.Symbol) and str(reading) in model.state_names \
                and str(reading) not in integrated:
            inputs.append(s)
        elif _states_in(flat_readings[s], model) <= set(integrated):
            compared.append(s)
        else:
            return None
    if len(compared) != 1:
        return None
    fixed = {str(readings[s]) for s in inputs}
    for st in integrated:
        if not _states_in(flat_derivs[st], model) <= set(integrated) | fixed:
            return None  # an algebraic loop through a state: derivative causality
    faults = tuple(f for f in r.faults
                   if any(sp.Symbol(f, real=True) in _free(r.rels[i]) for i in eqs))
    name = f"r_{compared[0]}" + (f"|{','.join(inputs)}" if inputs else "")
    ordered = tuple(s for s in model.state_names if s in integrated)
    return ResidualGenerator(name, compared[0], ordered, tuple(inputs), tuple(labels), faults)


def _free(rel: Any) -> set[sp.Basic]:
    return set() if isinstance(rel, list) else set(rel.free_symbols)


@functools.lru_cache(maxsize=32)
def residual_generators(model: PlantModel, kind: ResidualKind = "simulation"
                        ) -> tuple[ResidualGenerator, ...]:
    """The residual generators of a residual set, derived from the equations.

    Parameters
    ----------
    model : PlantModel
    kind : {"simulation", "structured"}
        ``"simulation"``: one per sensor, the model run from the known inputs;
        ``"structured"``: every MSO computable by integration.

    Returns
    -------
    tuple of ResidualGenerator

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> [g.name for g in residual_generators(load_plant_model("hst"))]
    ['r_Ps', 'r_omega_m']
    """
    if kind not in RESIDUAL_KINDS:
        raise ConfigError(f"unknown residual kind {kind!r}; allowed: {', '.join(RESIDUAL_KINDS)}")
    return derived_cache.cached(
        derived_cache.plant_key(model), f"generators:{kind}",
        lambda: _derive_generators(model, kind),
        lambda gens: [dataclasses.asdict(g) for g in gens],
        lambda data: tuple(ResidualGenerator(
            str(d["name"]), str(d["sensor"]), *(tuple(str(v) for v in d[k]) for k in (
                "integrated", "inputs", "equations", "faults"))) for d in data))


def _derive_generators(model: PlantModel, kind: ResidualKind) -> tuple[ResidualGenerator, ...]:
    r = _relations(model)
    n = len(r.labels)
    sensor_rows = {lab[7:]: i for i, lab in enumerate(r.labels) if lab.startswith("sensor:")}
    out: list[ResidualGenerator] = []
    if kind == "simulation":
        for s, row in sensor_rows.items():
            keep = [i for i in range(n) if i == row or i not in sensor_rows.values()]
            msos = [[keep[i] for i in mso] for mso in _fdt_model(r, keep).MSO()]
            eqs = sorted({i for mso in msos if row in mso for i in mso})
            gen = _generator(model, r, eqs) if eqs else None
            if gen is None:
                raise ModelError(f"model {model.name!r}: sensor {s!r} cannot be predicted by "
                                 "simulating the model from its known inputs")
            out.append(gen)
    elif kind == "structured":
        seen = set()
        for mso in _fdt_model(r, range(n)).MSO():
            gen = _generator(model, r, [int(i) for i in mso])
            if gen is not None and gen.name not in seen:
                seen.add(gen.name)
                out.append(gen)
    else:
        raise ConfigError(f"unknown residual kind {kind!r}; allowed: {', '.join(RESIDUAL_KINDS)}")
    return tuple(out)


@functools.lru_cache(maxsize=32)
def fault_signature(model: PlantModel, kind: ResidualKind = "simulation") -> FaultSignature:
    """Fault signature matrix, Mb, Ib and isolability of a residual set.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> fsm = fault_signature(load_plant_model("hst"))
    >>> fsm.signature("Rv"), fsm.mb["Rv"], fsm.ib["Rv"]
    ((1, 1), 1, 0)
    """
    return derived_cache.cached(
        derived_cache.plant_key(model), f"signature:{kind}",
        lambda: _derive_signature(model, kind),
        lambda f: {"faults": list(f.faults), "residuals": list(f.residuals),
                   "matrix": f.matrix.tolist(), "isolable": f.isolable.tolist(),
                   "model_isolable": f.model_isolable.tolist()},
        lambda d: FaultSignature(
            tuple(str(v) for v in d["faults"]), tuple(str(v) for v in d["residuals"]),
            np.array(d["matrix"], dtype=np.int64).reshape(len(d["faults"]), len(d["residuals"])),
            np.array(d["isolable"], dtype=np.bool_).reshape(len(d["faults"]), len(d["faults"])),
            np.array(d["model_isolable"], dtype=np.bool_).reshape(len(d["faults"]),
                                                                  len(d["faults"]))))


def _derive_signature(model: PlantModel, kind: ResidualKind) -> FaultSignature:
    gens = residual_generators(model, kind)
    r = _relations(model)
    fdt_model = _fdt_model(r, range(len(r.labels)))
    matrix = np.array([[int(f in g.faults) for g in gens] for f in r.faults], dtype=np.int64)
    matrix = matrix.reshape(len(r.faults), len(gens))
    not_isolable = fdt_model.IsolabilityAnalysisFSM(matrix.T, permute=False)
    model_not_isolable = fdt_model.IsolabilityAnalysis(causality="int")
    return FaultSignature(r.faults, tuple(g.name for g in gens), matrix,
                          np.asarray(not_isolable) == 0, np.asarray(model_not_isolable) == 0)


def suspects(fsm: FaultSignature, fired: Iterable[str]) -> tuple[str, ...]:
    """First-level isolation under the single-fault hypothesis.

    The suspects are the monitorable faults whose signature holds every fired
    residual (a residual that did not fire exonerates nothing: a small fault may
    stay under one threshold).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> fsm = fault_signature(load_plant_model("hst"))
    >>> suspects(fsm, ["r_Ps"])
    ('Dp', 'Rlkgp', 'Dm', 'Rlkgm', 'Rv', 'Tld')
    """
    fired = list(fired)
    if not fired:
        return ()
    cols = [fsm.residuals.index(name) for name in fired]
    return tuple(f for i, f in enumerate(fsm.faults) if fsm.matrix[i, cols].all())
