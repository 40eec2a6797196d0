"""The flow of one test (SPEC A8), as library functions the CLI calls.

run test -> estimate -> fit >= threshold? (else store as rejected and report)
-> physical parameters -> store in history -> symptoms against the baseline
-> diagnose -> go / advisory / no-go for the operator, faults for maintenance.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from condmon.diagnose.diagnoser import Diagnosis, diagnose
from condmon.diagnose.rules import RuleBase, load_rules
from condmon.errors import DataError
from condmon.identify.estimate import EstimateResult, estimate
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD
from condmon.io.records import read_record
from condmon.models.registry import get_model
from condmon.monitor.baseline import MIN_BASELINE_TESTS, Baseline, make_baseline
from condmon.monitor.fuzzy import MonitorConfig, compute_symptoms, load_monitor_config
from condmon.store.db import DuplicateTestError, HistoryStore, file_hash, frame_hash

__all__ = ["EstimateOptions", "AddedTest", "BaselineAddResult", "CheckResult",
           "add_baseline_tests", "current_baseline", "check_test", "RecordLike"]

RecordLike = str | Path | pd.DataFrame
Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class EstimateOptions:
    """How each record is estimated (see :func:`condmon.estimate`).

    ``model`` None: the unit's model (the one its history was started with),
    else ``dc-motor``.
    """

    model: str | None = None
    method: str = "sriv"
    gamma: float | None = None
    excitation: Sequence[str] | str | None = "auto"
    fit_threshold: float = DEFAULT_FIT_THRESHOLD
    columns: dict[str, str] | None = None
    route: str | None = None
    constants: dict[str, float] | None = None

    def run(self, record: RecordLike) -> tuple[EstimateResult, str]:
        """Read (if a path), estimate; returns the result and the record's SHA-256."""
        if isinstance(record, pd.DataFrame):
            df, digest = record, frame_hash(record)
            source = str(record.attrs.get("source", "record"))
        else:
            df, digest, source = read_record(record, self.columns), file_hash(record), str(record)
        res = estimate(df, self.model or "dc-motor", method=self.method, gamma=self.gamma,
                       excitation=self.excitation, fit_threshold=self.fit_threshold,
                       columns=self.columns if isinstance(record, pd.DataFrame) else None,
                       source=source, route=self.route, constants=self.constants)
        return res, digest


@dataclass(frozen=True)
class AddedTest:
    """One record offered to the baseline: stored, rejected, a duplicate or refused.

    ``refused`` records (a likely unit or sign error against the baseline so
    far) are not stored; their ``test_id`` is -1 and ``reason`` says why.
    """

    source: str
    test_id: int
    accepted: bool
    duplicate: bool
    reason: str | None = None
    refused: bool = False


@dataclass(frozen=True)
class BaselineAddResult:
    """Outcome of adding healthy tests.

    Attributes
    ----------
    tests : tuple of AddedTest
    baseline : Baseline or None
        The unit's baseline after the additions (None while fewer than 3
        accepted healthy tests exist).
    baseline_id : int or None
    message : str
    """

    tests: tuple[AddedTest, ...]
    baseline: Baseline | None
    baseline_id: int | None
    message: str


def current_baseline(store: HistoryStore, unit: str) -> tuple[Baseline, list[int]]:
    """Baseline of a unit from its accepted healthy tests (and their ids).

    Raises
    ------
    DataError
        Fewer than 3 accepted healthy tests.
    """
    ids, table = store.accepted_estimates(unit, role="baseline")
    if len(ids) < MIN_BASELINE_TESTS:
        raise DataError(f"unit {unit!r} has {len(ids)} accepted healthy test(s); a baseline "
                        f"needs at least {MIN_BASELINE_TESTS}: add them with "
                        f"`condmon baseline add REC... --unit {unit}`")
    return make_baseline(table.to_numpy(), list(table.columns)), ids


def _unit_options(store: HistoryStore, unit: str, opts: EstimateOptions) -> EstimateOptions:
    """Options with the unit's model filled in; refuses a record offered with
    another model than the one the unit's history was started with."""
    stored = store.unit_model(unit)
    if opts.model is None:
        return dataclasses.replace(opts, model=stored or "dc-motor")
    if stored is not None:
        machine = get_model(opts.model)
        if stored not in (machine.name, machine.origin):
            raise DataError(f"unit {unit!r} is monitored with model {stored!r}; this record "
                            f"was offered with {opts.model!r} (omit --model to use the "
                            "unit's)")
    return opts


def _existing_baseline(store: HistoryStore, unit: str) -> Baseline | None:
    """The unit's current baseline, or None while it has fewer than 3 healthy tests."""
    try:
        return current_baseline(store, unit)[0]
    except DataError:
        return None


def _unit_error(res: EstimateResult, baseline: Baseline) -> str | None:
    """Why a test's parameters jump beyond what is believable or flip sign
    against the baseline ("likely unit or sign error ..."), or None."""
    return get_model(res.model_key).spec.plausibility.check_against_baseline(
        res.parameters, dict(zip(baseline.parameters, baseline.mean)), res.units)


def add_baseline_tests(store: HistoryStore, unit: str, records: Sequence[RecordLike],
                       options: EstimateOptions | None = None,
                       progress: Progress | None = None) -> BaselineAddResult:
    """Estimate healthy records and store them as the unit's baseline tests.

    Each record is committed on its own, so an interruption keeps every record
    finished before it. A record already in the unit's history is skipped. The
    baseline (mean, sample standard deviation) is recomputed from every
    accepted healthy test once at least 3 exist.
    """
    opts = _unit_options(store, unit, options or EstimateOptions())
    added = []
    for i, rec in enumerate(records):
        name = str(rec) if not isinstance(rec, pd.DataFrame) else rec.attrs.get("source", f"record {i}")
        if progress is not None:
            progress(i, len(records), str(name))
        res, digest = opts.run(rec)
        prior = _existing_baseline(store, unit) if res.accepted else None
        why = None if prior is None else _unit_error(res, prior)
        if why is not None:
            added.append(AddedTest(res.source, -1, False, False, why, refused=True))
            continue
        try:
            tid = store.add_test(unit, res, role="baseline", digest=digest)
            added.append(AddedTest(res.source, tid, res.accepted, False, res.reason))
        except DuplicateTestError as dup:
            added.append(AddedTest(res.source, dup.test_id, res.accepted, True,
                                   "already in the history"))
    if progress is not None:
        progress(len(records), len(records), "")
    try:
        baseline, ids = current_baseline(store, unit)
    except DataError as err:
        return BaselineAddResult(tuple(added), None, None, str(err))
    bid = store.save_baseline(unit, baseline, ids)
    return BaselineAddResult(tuple(added), baseline, bid,
                             f"baseline of {unit!r} from {baseline.n} accepted healthy tests")


@dataclass(frozen=True)
class CheckResult:
    """Outcome of checking one test against the unit's baseline.

    Attributes
    ----------
    unit : str
    test_id : int
    estimate : EstimateResult
    status : {"go", "advisory", "no-go", "retest"}
        "retest" when the test was rejected (fit below threshold): it is stored
        as rejected and changes no symptom or trend.
    baseline : Baseline or None
    percent_change : dict of str to float
        Against the baseline mean. [%]
    symptoms : dict
        ``{param: {"high", "low"}}`` before preprocessing.
    diagnosis : Diagnosis or None
    """

    unit: str
    test_id: int
    estimate: EstimateResult
    status: str
    baseline: Baseline | None = None
    percent_change: dict[str, float] = field(default_factory=dict)
    symptoms: dict[str, dict[str, float]] = field(default_factory=dict)
    diagnosis: Diagnosis | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result (the ``condmon check --json`` document)."""
        est = self.estimate.to_dict()
        return {
            "unit": self.unit,
            "test_id": self.test_id,
            "source": self.estimate.source,
            "status": self.status,
            "accepted": self.estimate.accepted,
            "reason": self.estimate.reason,
            "fit_percent": est["fit_percent"],
            "fits": est["fits"],
            "parameters": est["parameters"],
            "std_errors": est["std_errors"],
            "percent_change": self.percent_change,
            "symptoms": self.symptoms,
            "faults": ([] if self.diagnosis is None else
                       [f.to_dict() for f in self.diagnosis.faults]),
            "summary": (self.diagnosis.summary if self.diagnosis is not None else
                        f"retest: {self.estimate.reason}"),
            "condition": None if self.diagnosis is None else self.diagnosis.condition,
            "preprocessing_applied": ([] if self.diagnosis is None
                                      else list(self.diagnosis.applied)),
            "baseline": None if self.baseline is None else self.baseline.to_dict(),
            "method": est["method"],
            "closed_loop_instruments": est["closed_loop_instruments"],
            "notes": est["notes"],
        }


def check_test(store: HistoryStore, unit: str, record: RecordLike,
               options: EstimateOptions | None = None, monitor: MonitorConfig | None = None,
               rules: RuleBase | None = None, dry_run: bool = False) -> CheckResult:
    """Estimate a test, store it, compute symptoms against the baseline and diagnose.

    The monitor breakpoints and the rule base are the model's own (declared in
    its ``[monitor]`` table), the shipped DC-motor ones otherwise, unless given.
    ``dry_run``: estimate and diagnose, store nothing (``test_id`` is -1; a
    record already in the history is checked again).

    Raises
    ------
    DataError
        The unit has no baseline yet (fewer than 3 accepted healthy tests), or
        the test's parameters jump beyond the model's believable change or flip
        sign against the baseline (a likely unit or sign error; nothing stored).
    DuplicateTestError
        The record is already in the unit's history.
    """
    opts = _unit_options(store, unit, options or EstimateOptions())
    machine = get_model(opts.model or "dc-motor")
    cfg = monitor or load_monitor_config(machine.breakpoints)
    rb = rules or load_rules(machine.rules)
    baseline, ids = current_baseline(store, unit)
    rb.check_parameters(baseline.parameters)
    res, digest = opts.run(record)
    why = _unit_error(res, baseline) if res.accepted else None
    if why is not None:
        raise DataError(f"{res.source}: refused, {why}; nothing was stored")
    if not res.accepted:
        tid = -1 if dry_run else store.add_test(unit, res, role="check", digest=digest)
        return CheckResult(unit, tid, res, "retest", baseline)
    values = np.array([res.parameters[p] for p in baseline.parameters])
    ses = np.array([res.std_errors[p] for p in baseline.parameters])
    sym = compute_symptoms(values, baseline, cfg, ses)
    row = sym.row(0)
    diag = diagnose(sym.to_dict(0), rb)
    if dry_run:
        tid = -1
    else:
        bid = store.save_baseline(unit, baseline, ids)
        tid = store.add_test(unit, res, role="check", digest=digest, symptoms=row,
                             baseline_id=bid, diagnosis=diag)
    return CheckResult(unit, tid, res, diag.status, baseline,
                       {p: v["percent_change"] for p, v in row.items()},
                       sym.to_dict(0), diag)
