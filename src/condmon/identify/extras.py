"""What a record adds to an estimate beside the route's parameters.

- :func:`systematic_part`: how far the sensors' stated accuracy could move
  each value (the systematic part shown beside the standard error);
- :func:`with_features`: the declared signal features and operating
  conditions over the estimate's windows.

Both take one record or several estimated together.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import CondmonError, DataError
from condmon.identify.result import EstimateResult
from condmon.io.records import Record
from condmon.models.features import FeatureSpec
from condmon.models.machine import Machine

__all__ = ["systematic_part", "with_features"]

FloatArray = NDArray[np.float64]


def systematic_part(res: EstimateResult, records: Sequence[Record],
                    accuracy: Mapping[str, float],
                    run: Callable[[list[Record]], EstimateResult]) -> dict[str, float]:
    """The systematic part of each of ``res``'s stored values from its sensors'
    stated accuracy (see :attr:`EstimateResult.systematic`).

    A sensor's error within its stated accuracy ``a`` is taken two ways, and
    the one that moves a value more counts: an offset ``+a`` (zero drift), and
    a span error that grows with the reading and reaches ``a`` at the
    record's largest reading (the column times ``1 + a / max|x|``). The
    records are estimated again with each (``run``); the value's change is
    how far that sensor moves it at its bound. Records estimated together (a
    stroke each way) take the same error: one gauge's drift over the seconds
    between them is the same in each, and an estimate that separates a load
    torque from the friction puts an offset in the load torque, not in the
    friction, where only the span error's small part remains. The systematic
    part is the root-sum-square of the changes over the sensors (independent
    sensors seldom reach their bounds together, in the directions that add).
    Written here, not taken from a library: the uncertainties package
    propagates through functions of numbers, not through an estimator run on a
    record. A value the changed records do not give (their estimate refused)
    gets NaN: its systematic part is not known.

    Example
    -------
    A balance ``F = c (pA - pB)`` read from two gauges of ±0.25 % of 200 bar:
    each gauge's 0.5 bar moves ``F`` by ``c`` × 0.5 bar, so the systematic part
    is ``c × 0.5 bar × √2`` whatever the noise.
    """
    base = res.stored_values()
    total = dict.fromkeys(base, 0.0)
    for column, a in accuracy.items():
        if column == "t" or not all(column in r.columns for r in records):
            continue
        largest = max(float(np.max(np.abs(r.columns[column]))) for r in records)
        errors: list[Callable[[FloatArray], FloatArray]] = [lambda x: x + a]
        if largest > 0.0:
            errors.append(lambda x: x * (1.0 + a / largest))
        worst = dict.fromkeys(base, 0.0)
        for error in errors:
            changed = [Record({**r.columns, column: error(r.columns[column])}, r.dt, r.source)
                       for r in records]
            try:
                moved = run(changed).stored_values()
            except CondmonError:
                moved = {}
            for key, (value, _) in base.items():
                other = moved.get(key, (math.nan, math.nan))[0]
                # (a NaN, once in, stays: max keeps the first NaN it meets)
                worst[key] = max(worst[key], abs(float(other) - float(value)), key=_nan_first)
        for key, change in worst.items():
            total[key] += change ** 2
    # a value no stated accuracy moves (a feature of another channel) has none: its
    # sensors' accuracy is not stated, not zero
    return {k: math.sqrt(v) for k, v in total.items() if v != 0.0}


def _nan_first(x: float) -> float:
    """Order for max() that puts a NaN above every number."""
    return math.inf if math.isnan(x) else x


def with_features(res: EstimateResult, rec: Record | Sequence[Record], machine: Machine,
                  metadata: Mapping[str, Any] | None = None,
                  available: Sequence[str] | None = None) -> EstimateResult:
    """``res`` with the signal features and the operating conditions
    ``machine`` declares, computed over ``rec``'s windows
    (:func:`condmon.features.compute_features`) and from ``metadata``;
    ``res`` itself when it declares none. ``available``: the record file's
    columns, named when a channel is missing. Several records estimated
    together (:func:`~condmon.identify.estimate.estimate_joint`) give each
    feature over the windows of all of them, under the estimate's regime
    (``vib1@forward + reverse``).

    Raises
    ------
    DataError
        A condition's metadata field that is not a number.
    """
    if not machine.features and not machine.conditions:
        return res
    from condmon.features import compute_features

    channels = [c.feature for c in machine.conditions if c.feature is not None]
    if isinstance(rec, Record):
        rec, spans = rec, [(w.regime, w.first, w.stop, w.used) for w in res.windows] \
            or [("", 0, len(rec), True)]
    else:
        rec, spans = _joined(list(rec), res, (*machine.features, *channels))
    est = compute_features(rec.columns, 1.0 / rec.dt, spans, machine.features, rec.source,
                           machine.plant.source, available=available)
    conds = compute_features(rec.columns, 1.0 / rec.dt, spans, channels, rec.source,
                             machine.plant.source, what="condition", available=available)
    conditions = dict(conds.values)
    notes = [*res.notes, *est.notes, *conds.notes]
    for c in machine.conditions:
        if c.metadata is None:
            continue
        value = (metadata or {}).get(c.metadata)
        if value is None:
            notes.append(f"condition {c.name} not known: the record has no metadata field "
                         f"{c.metadata!r}")
            continue
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = math.nan
        if isinstance(value, bool) or not math.isfinite(number):
            raise DataError(f"{rec.source}: condition {c.name!r} reads metadata field "
                            f"{c.metadata!r} = {value!r}, which is not a finite number")
        conditions[c.name] = (number, 0.0)
    # a condition's unit beside the features' (what unit_of reads)
    return dataclasses.replace(res, features=est.values,
                               feature_units={**conds.units, **est.units},
                               conditions=conditions, notes=tuple(notes))


def _joined(records: list[Record], res: EstimateResult, specs: Sequence[FeatureSpec]
            ) -> tuple[Record, list[tuple[str, int, int, bool]]]:
    """One record of the channels ``specs`` read, the records' rows one after
    another, and their windows in it: a used window under the estimate's
    regime (the records' windows pooled), the others under their own."""
    names = {s.channel for s in specs}
    cols = {c: np.concatenate([r.columns[c] for r in records]) for c in names
            if all(c in r.columns for r in records)}
    spans: list[tuple[str, int, int, bool]] = []
    offset = 0
    for r in records:
        for w in res.windows:
            if w.source == r.source:
                label = res.regime if w.used and res.regime else w.regime
                spans.append((label, w.first + offset, w.stop + offset, w.used))
        offset += len(r)
    cols["t"] = records[0].dt * np.arange(offset, dtype=np.float64)
    source = " + ".join(r.source for r in records)
    return Record(cols, records[0].dt, source), spans
