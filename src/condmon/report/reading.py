"""Reads a report needs that the store has no method for (read-only)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["CheckFault", "check_faults", "model_units"]


@dataclass(frozen=True)
class CheckFault:
    """One fault of a check's diagnosis.

    Attributes
    ----------
    name : str
    degree : float
        Degree of the fault's condition. [0..1]
    severity : str
        ``major`` or ``minor``.
    advice : str
    """

    name: str
    degree: float
    severity: str
    advice: str


def check_faults(store: Any, test_id: int, baseline_id: Any) -> tuple[CheckFault, ...]:
    """The faults of test ``test_id``'s evaluation against baseline ``baseline_id``,
    largest degree first.

    A check keeps one evaluation per baseline it was evaluated against; the
    one a report shows is the history row's ``baseline_id``. Without one (an
    unchecked test) there are no faults.

    Parameters
    ----------
    store : HistoryStore
    test_id : int
    baseline_id : int or None

    Returns
    -------
    tuple of CheckFault
    """
    import pandas as pd
    import sqlalchemy as sa

    from condmon.store import schema as S

    if baseline_id is None or pd.isna(baseline_id):
        return ()
    f = S.diagnosis_faults
    q = (sa.select(f.c.name, f.c.degree, f.c.severity, f.c.advice)
         .where(f.c.test_id == int(test_id), f.c.baseline_id == int(baseline_id))
         .order_by(f.c.degree.desc(), f.c.name))
    with store.engine.connect() as conn:
        rows = conn.execute(q).all()
    return tuple(CheckFault(str(r[0]), float(r[1]), str(r[2]), str(r[3])) for r in rows)


def model_units(machine: Any) -> dict[str, str]:
    """Unit of every parameter of ``machine`` (a :class:`~condmon.models.machine.Machine`):
    the declared parameters' and the reported (derived) quantities'.

    A regime's parameter (``Tc@forward``) takes its parameter's unit
    (:func:`condmon.models.regimes.split_key`).
    """
    return {**machine.plant.parameter_units(), **machine.monitored_units}


def judged_monitor(machine: Any, baseline: Any, hist: Any, monitor: Any = None) -> Any:
    """The breakpoints a unit's checks were judged with, for its figures: the
    model's monitor (or ``monitor``), raised to the baseline's scatter with
    the checks' typical systematic part, keyed by the history's parameters.
    ``baseline``: the unit's active :class:`~condmon.monitor.baseline.Baseline` (or None)."""
    from condmon.monitor.generic import machine_monitor, typical_systematic, with_scatter

    cfg = monitor or machine_monitor(machine, baseline)
    cfg = cfg if baseline is None else with_scatter(cfg, baseline, typical_systematic(hist))
    return cfg.keyed([c for c in hist.columns if f"{c}_se" in hist.columns])
