"""Which column's unit would explain a refused estimate: "current in mA?".

A record written in another unit than its declaration says (mA for A, rpm
for rad/s, kPa for Pa) gives an estimate that is refused: not physically
possible, not a measurement, or beyond the believable change against the
unit's baseline. The refusal is right, but a user needs to know which column
to fix. Each measured column is read again as if it held one of the units a
rig commonly writes instead (``condmon/data/unit_errors.toml``), the record
is estimated again, and a reading that then gives an estimate the caller
accepts is named. Nothing is converted: the suspicion is said, the record
stays refused.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from condmon.errors import CondmonError
from condmon.io.columns import Columns, column_values

__all__ = ["UnitSuspect", "unit_suspects", "unit_alternatives", "suspect_text"]

# A user's declaration may write its units as it likes; these spellings are
# the same unit as the table's keys.
_SPELLINGS = {"amp": "A", "amps": "A", "volt": "V", "volts": "V",
              "n*m": "N m", "nm": "N m", "n.m": "N m", "rad/sec": "rad/s",
              "pascal": "Pa", "m3/s": "m^3/s", "m**3/s": "m^3/s"}


# A re-read estimate within 25 % of the reference in every parameter (the
# largest healthy spread between units the shipped declarations state) ends
# the search: each further reading costs a whole estimate.
_CLOSE = math.log(1.25)


@dataclass(frozen=True)
class UnitSuspect:
    """One column read in another unit, and what the estimate then says.

    Attributes
    ----------
    column : str
        The model column.
    description : str
        What it measures (the declaration's description).
    unit : str
        The unit it may hold instead of its declared one (``mA``).
    declared : str
        Its declared unit (``A``).
    si : float
        One of ``unit`` in ``declared``. [declared unit]
    score : float
        How far the re-read estimate stays from the reference: the largest
        ``|log(value / reference)|`` of its parameters (0 without one). [-]
    """

    column: str
    description: str
    unit: str
    declared: str
    si: float
    score: float = 0.0

    def __str__(self) -> str:
        what = f" ({self.description})" if self.description else ""
        return f"column {self.column!r}{what} in {self.unit}?"


@cache
def _table() -> dict[str, tuple[tuple[str, float], ...]]:
    text = resources.files("condmon.data").joinpath("unit_errors.toml").read_text("utf-8")
    units = tomllib.loads(text)["units"]
    return {k: tuple((str(e["name"]), float(e["si"])) for e in v) for k, v in units.items()}


def unit_alternatives(unit: str) -> tuple[tuple[str, float], ...]:
    """The units a rig may write for a column declared in ``unit``, each with
    its value in ``unit``.

    Example
    -------
    >>> unit_alternatives("A")
    (('mA', 0.001),)
    >>> unit_alternatives("furlong")
    ()
    """
    key = unit.strip()
    key = _SPELLINGS.get(key.lower(), key)
    return _table().get(key, ())


def unit_suspects(frame: Any, columns: Mapping[str, tuple[str, str]],
                  estimate: Callable[[Columns], Any], accept: Callable[[Any], bool],
                  reference: Mapping[str, float] | None = None, limit: int = 2
                  ) -> tuple[UnitSuspect, ...]:
    """The column units that would explain a refused estimate, best first.

    Parameters
    ----------
    frame : DataFrame or Columns
        The record as estimated (model columns, declared units).
    columns : mapping
        ``{column: (declared unit, description)}`` of the measured columns to
        try (sensors and inputs; not the time).
    estimate : callable
        Estimates a record given as :class:`~condmon.io.columns.Columns`.
    accept : callable
        Whether an estimate would have been taken (accepted, believable).
    reference : mapping, optional
        Values to rank suspects by (a baseline's means): the closer, the first.
    limit : int
        Most suspects returned.

    Returns
    -------
    tuple of UnitSuspect
        Empty when no single column's unit explains the refusal. The search
        stops at the first reading whose estimate lies within 25 % of the
        reference in every parameter (the first accepted one without a
        reference).
    """
    base = {c: column_values(frame, c) for c in frame.columns}
    attrs = dict(getattr(frame, "attrs", {}) or {})
    found = []
    for name, (unit, description) in columns.items():
        if name not in base:
            continue
        for alt, si in unit_alternatives(unit):
            values = dict(base)
            values[name] = base[name] * si
            try:
                res = estimate(Columns(values, attrs))
            except (CondmonError, ArithmeticError, ValueError, np.linalg.LinAlgError):
                continue   # a reading that cannot be estimated is no suspect
            if not accept(res):
                continue
            found.append(UnitSuspect(name, description, alt, unit, si,
                                     _distance(res, reference)))
            if found[-1].score <= _CLOSE:   # as near the reference as a healthy unit: enough
                return (found[-1],)
    found.sort(key=lambda s: s.score)
    return tuple(found[:limit])


def _distance(res: Any, reference: Mapping[str, float] | None) -> float:
    if not reference:
        return 0.0
    gaps = [abs(math.log(v / reference[k])) for k, (v, _) in res.stored_values().items()
            if k in reference and reference[k] and v and np.sign(v) == np.sign(reference[k])
            and math.isfinite(v)]
    return max(gaps) if gaps else math.inf


def suspect_text(suspects: tuple[UnitSuspect, ...]) -> str:
    """The suspects in one clause (empty when none).

    Example
    -------
    >>> suspect_text((UnitSuspect("I", "armature current", "mA", "A", 1e-3),))
    "column 'I' (armature current) in mA? (converted to A, the record's estimate is accepted)"
    """
    return "; or ".join(f"{s} (converted to {s.declared}, the record's estimate is accepted)"
                        for s in suspects)
