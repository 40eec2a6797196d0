"""The unit of work of a fleet run: one record, read and estimated (or isolated) on a worker.

This module holds what is shipped to the distributed engine's workers:
:class:`RecordTask` (a record's path, its unit's model and the options),
:func:`process_record` (a plain module-level function, so that it pickles,
which reads the record and estimates its parameters or isolates a fault,
touching no database) and :class:`RecordOutcome` (the small picklable answer:
the estimate or the isolation, how the record is known, or the error text).
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings
from dataclasses import dataclass, field
from datetime import datetime
from typing import TYPE_CHECKING, Literal

from condmon.errors import CondmonError
from condmon.io.raw import one_line
from condmon.workflows.records import EstimateOptions, RecordKey

if TYPE_CHECKING:
    from condmon.diagnose.isolation import IsolationResult, IsolationSettings
    from condmon.identify.estimate import EstimateResult
    from condmon.models.declared import PlantModel

__all__ = ["RecordTask", "RecordOutcome", "process_record", "process_records"]

Kind = Literal["estimate", "isolate"]


@dataclass(frozen=True)
class RecordTask:
    """What a worker needs to process one record.

    Attributes
    ----------
    unit : str
    path : str
        The record file (a path the workers can read).
    kind : {"estimate", "isolate"}
        Estimate the model's parameters, or isolate a fault (a plant model).
    model : str
        Model name or declaration file.
    options : EstimateOptions
        How to read and estimate (``columns`` applies to isolations too).
    test_date : datetime or None
        When the test was run, if given (else the record's own date, if any).
    known : frozenset of str
        Content hashes already in the unit's history: such a record is
        recognised after reading and not processed.
    """

    unit: str
    path: str
    kind: Kind
    model: str
    options: EstimateOptions = field(default_factory=EstimateOptions)
    test_date: datetime | None = None
    known: frozenset[str] = frozenset()


@dataclass(frozen=True)
class RecordOutcome:
    """What a worker returns for one record (small and picklable).

    Attributes
    ----------
    unit : str
    path : str
    key : RecordKey or None
        How the record is known (None when it could not be read).
    estimate : EstimateResult or None
        For ``kind == "estimate"``.
    isolation : IsolationResult or None
        For ``kind == "isolate"``.
    error : str or None
        Why the record could not be processed (one line naming the file).
    known : bool
        Its content is already in the unit's history (nothing processed).
    warnings : tuple of str
        Warnings raised while reading or processing it.
    seconds : float
        Time on the worker. [s]
    """

    unit: str
    path: str
    key: RecordKey | None = None
    estimate: EstimateResult | None = None
    isolation: IsolationResult | None = None
    error: str | None = None
    known: bool = False
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0


def _named(path: str, message: str) -> str:
    """``message`` as one line that names the file."""
    text = one_line(message, None)
    return text if path in text else f"{path}: {text}"


@functools.lru_cache(maxsize=16)
def _plant(model: str) -> PlantModel:
    from condmon.models.registry import load_plant_model

    return load_plant_model(model)


@functools.lru_cache(maxsize=1)
def _isolation_settings() -> IsolationSettings:
    from condmon.diagnose.isolation import IsolationSettings

    return IsolationSettings.load()


def process_record(task: RecordTask) -> RecordOutcome:
    """Read one record and estimate it (or isolate a fault in it); never raises
    on the record: a failure becomes the outcome's ``error``.

    This is the unit of work shipped to a worker: a pure function of the
    record's file and the options, touching no database. An isolation runs
    its suspects one after the other (a worker is one process already).

    Parameters
    ----------
    task : RecordTask

    Returns
    -------
    RecordOutcome

    Example
    -------
    >>> out = process_record(RecordTask("EMA-1", "missing.csv", "estimate", "dc-motor"))
    >>> out.error
    'missing.csv: file not found'
    """
    from condmon.workflows.records import record_key

    started = time.perf_counter()
    key = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            opts = dataclasses.replace(task.options, model=task.model)
            df = opts.read(task.path)  # the record settings applied once, here
            key = record_key(df, task.path, task.test_date, opts.metadata)
            if key.content in task.known:
                return RecordOutcome(task.unit, task.path, key, known=True,
                                     seconds=time.perf_counter() - started)
            if task.kind == "isolate":
                from condmon.diagnose.isolation import isolate
                from condmon.io.columns import Columns

                frame = df.to_frame() if isinstance(df, Columns) else df
                iso = isolate(frame, _plant(task.model), settings=_isolation_settings(),
                              workers=1, source=task.path)
                return RecordOutcome(task.unit, task.path, key, isolation=iso,
                                     warnings=_texts(caught),
                                     seconds=time.perf_counter() - started)
            res = opts.estimate_parsed(df, task.path)
            return RecordOutcome(task.unit, task.path, key, estimate=res,
                                 warnings=_texts(caught), seconds=time.perf_counter() - started)
        except CondmonError as exc:
            why = str(exc)
        except FileNotFoundError:
            why = "file not found"
        except OSError as exc:
            why = f"cannot read: {exc.strerror or exc}"
        except Exception as exc:  # noqa: BLE001 - a numerical failure is this record's alone
            why = f"{type(exc).__name__}: {exc}"
    return RecordOutcome(task.unit, task.path, key, error=_named(task.path, why),
                         warnings=_texts(caught), seconds=time.perf_counter() - started)


def process_records(tasks: tuple[RecordTask, ...]) -> list[RecordOutcome]:
    """:func:`process_record` of each task, in order: a few records per unit
    of work shipped to a worker, so the engine's cost per task (scheduling,
    messages) is shared among them."""
    return [process_record(task) for task in tasks]


def _texts(caught: list[warnings.WarningMessage]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(one_line(str(w.message), None) for w in caught))

