"""A machine's cycle written as several files: which records make one test.

A declaration's ``[estimation] cycle`` names the regimes one test holds (the
hydraulic actuator's ``forward`` and ``reverse``: its stand writes one stroke
per file, the direction alternating). :func:`cycles_of` takes records in time
order (their dates, when every record has one: a file name's time, a time
column; else the order given) and joins them until they hold a used window
of each; a record that repeats a regime the open test already holds (a record
the rig did not keep between them) starts a new test, and the unfinished one
is left out and said so, never joined across the gap.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from condmon.errors import CondmonError, DataError
from condmon.identify.estimate import used_regimes
from condmon.models.registry import get_model
from condmon.io.columns import Columns
from condmon.io.dates import parse_date
from condmon.workflows.records import Cycle, EstimateOptions, RecordLike

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["cycles_of", "one_cycle", "record_by_record"]


def _name(rec: RecordLike, i: int) -> str:
    if isinstance(rec, (str, Path)):
        return str(rec)
    return str(rec.attrs.get("source", f"record {i + 1}"))


def cycles_of(opts: EstimateOptions, records: Sequence[RecordLike]
              ) -> tuple[list[RecordLike | Cycle], list[tuple[str, str]]]:
    """The tests ``records`` make under ``opts.model``'s ``[estimation] cycle``,
    and the records left out, each with why.

    A model without a cycle: each record is a test. A record that holds none
    of the cycle's regimes (only a hold) is a test of its own (it is
    estimated, and refused as such).

    Raises
    ------
    CondmonError
        A record that cannot be read or validated (naming the file).

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> tests, left = cycles_of(EstimateOptions(), [simulate_actuator(seed=1)])
    >>> len(tests), left
    (1, [])
    """
    machine = get_model(opts.model or "dc-motor")
    want = machine.spec.cycle
    if not want:
        return list(records), []
    tests: list[RecordLike | Cycle] = []
    left: list[tuple[str, str]] = []
    group: list[tuple[RecordLike, pd.DataFrame | Columns, str, tuple[str, ...]]] = []
    covered: set[str] = set()
    what = f"a test of {machine.name} is one cycle ({', '.join(want)}: [estimation] cycle)"

    def leave(why: str) -> None:
        for _, _, name, held in group:
            left.append((name, f"left out ({', '.join(held)} only): {why}; {what}"))

    seen = []
    for i, rec in enumerate(records):
        name = _name(rec, i)
        df = opts.read(rec) if isinstance(rec, (str, Path)) else opts.prepared(rec)
        held = tuple(r for r in used_regimes(df, machine, source=name, route=opts.route,
                                             metadata=opts.metadata, window=opts.window,
                                             constants=opts.constants)
                     if r in want)
        start = df.attrs.get("start_time")
        seen.append((rec, df, name, held, parse_date(str(start), name) if start else None))
    dates = [when for *_, when in seen if when is not None]
    if len(dates) == len(seen):   # in time order: a shell's glob is not
        seen = [seen[k] for k in sorted(range(len(seen)), key=dates.__getitem__)]   # stable
    for rec, df, name, held, _ in seen:
        if not held:
            tests.append(rec)
            continue
        if covered & set(held):
            leave(f"the next record ({name}) holds {', '.join(held)} again before the "
                  f"cycle's {', '.join(r for r in want if r not in covered)}")
            group, covered = [], set()
        group.append((rec, df, name, held))
        covered |= set(held)
        if covered >= set(want):
            tests.append(Cycle(tuple(r for r, *_ in group), tuple(d for _, d, *_ in group)))
            group, covered = [], set()
    if group:
        leave(f"no record after it holds the cycle's "
              f"{', '.join(r for r in want if r not in covered)}")
    return tests, left


def one_cycle(opts: EstimateOptions, cycle: Cycle) -> Cycle:
    """``cycle``'s records as the one test they must make (``check A B``), in
    time order, or an error saying what they make instead.

    Raises
    ------
    DataError
        Records that make no cycle, or more than one test, or leave one out
        (naming them and the cycle; nothing is stored).
    """
    tests, left = cycles_of(opts, cycle.records)
    if len(tests) == 1 and not left and isinstance(tests[0], Cycle) \
            and len(tests[0].records) == len(cycle.records):
        return tests[0]
    machine = get_model(opts.model or "dc-motor")
    made = ("no cycle" if not tests else f"{len(tests)} tests" if len(tests) > 1 else
             f"one test of {len(tests[0].records) if isinstance(tests[0], Cycle) else 1} "
             "of them")
    out = f" and leave {', '.join(n for n, _ in left)} out" if left else ""
    raise DataError(f"{cycle.source}: these records make {made}{out}; a test of "
                    f"{machine.name} is one cycle ({', '.join(machine.spec.cycle)}: "
                    "[estimation] cycle): check one cycle's records together; nothing was "
                    "stored")


def record_by_record(model: str | None, each: str = "record") -> str:
    """What a command that checks one record at a time (``fleet run``,
    ``watch``) says of a unit whose ``model`` declares a cycle: its tests
    there are single records (``each`` names them), not cycles. Empty when
    the model declares none (or cannot be loaded: the run says that itself).

    Example
    -------
    >>> record_by_record("dc-motor")
    ''
    """
    try:
        cycle = get_model(model or "dc-motor").spec.cycle
    except CondmonError:
        return ""
    return "" if not cycle else (
        f"its model declares a cycle ({', '.join(cycle)}: [estimation] cycle), but here each "
        f"{each} is its own test, checked against a baseline of single ones; "
        "`condmon baseline add` and `condmon check A B` estimate and check whole cycles")
