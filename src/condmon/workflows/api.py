"""One Python API over a unit history: :class:`History`, found as ``condmon.History``.

The commands a user types (``baseline add``, ``check``, ``history``,
``forecast``, ``units``, ``exclude``, ``unit set-model``, ``isolate``) are
methods here, over the same workflow functions the CLI calls, so a notebook
and a terminal give the same answers. Results show themselves in a notebook
(``_repr_html_``) and draw themselves (``.plot()`` returns a matplotlib
figure).

Example
-------
>>> import condmon, tempfile, os
>>> folder = tempfile.mkdtemp()
>>> files = []
>>> for seed in (1, 2, 3, 4):
...     path = os.path.join(folder, f"r{seed}.csv")
...     condmon.simulate_actuator(seed=seed).to_csv(path, index=False)
...     files.append(path)
>>> with condmon.History(os.path.join(folder, "h.db")) as h:
...     added = h.baseline_add("EMA-7", files[:3])
...     result = h.check("EMA-7", files[3])
...     result.status, len(h.history("EMA-7")), list(h.units()["unit"])
('go', 4, ['EMA-7'])
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import pandas as pd

from condmon._threads import one_blas_thread
from condmon.errors import CondmonError
from condmon.workflows.checks import CheckResult, check_test
from condmon.workflows.imports import ImportedUnit, import_table
from condmon.workflows.monitoring import BaselineAddResult, add_baseline_tests
from condmon.workflows.records import EstimateOptions, RecordLike

if TYPE_CHECKING:
    from condmon.diagnose.isolation import IsolationResult
    from condmon.simulate.compare import Comparison
    from condmon.models.machine import Machine
    from condmon.forecast.unit import UnitForecast
    from condmon.store.db import HistoryStore
    from condmon.workflows.manage import ChangeResult

__all__ = ["History", "Forecast", "load_model", "isolate", "validate"]

F = TypeVar("F", bound=Callable[..., Any])

#: A CLI option in a message (``--against 'X'``), with the space before its value
#: (``against='X'``); before a word that goes on the sentence (``--horizon must
#: be``) it is the bare name; ``my--file.csv`` is no option.
_OPTION = re.compile(r"(?<![\w-])--([a-z][a-z-]*)"
                     r"( (?!(?:must|is|are|needs|and|or|to|of)\b)(?=['\"\w]))?")

#: Options whose argument has another name in Python.
_RENAMED = {"date": "test_date", "set": "values", "params": "parameters"}


def _python_text(text: str) -> str:
    """``text`` with the CLI's options named as the Python call's arguments."""
    def python(m: re.Match[str]) -> str:
        name = _RENAMED.get(m.group(1), m.group(1)).replace("-", "_")
        # --set R=2 is values R=2 (its value is an assignment of its own)
        return name + (("" if not m.group(2) else " " if name == "values" else "="))

    return _OPTION.sub(python, text)


def _as_arguments(fn: F) -> F:
    """Let a method's errors name its arguments (``against='X'``), not the
    command line's options (``--against 'X'``) that the shared workflow
    functions quote: a notebook user has no options. The error is the same
    object (its type and attributes kept), its text rewritten."""
    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except CondmonError as err:
            if err.args and isinstance(err.args[0], str):
                err.args = (_python_text(err.args[0]), *err.args[1:])
            raise

    return wrapped  # type: ignore[return-value]


@dataclass(frozen=True)
class Forecast:
    """A unit's forecast to no-go, as ``condmon forecast`` gives it.

    Attributes
    ----------
    result : UnitForecast
        Every parameter's forecast (:class:`condmon.forecast.unit.UnitForecast`):
        remaining life in ``result.by`` (tests, days or hours) with its 90 %
        interval.
    """

    result: UnitForecast

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the ``condmon forecast --json`` document)."""
        return self.result.to_dict()

    def _repr_html_(self) -> str:
        from condmon.report.notebook import forecast_html

        return forecast_html(self.result)


class History:
    """A unit history (a SQLite file or a PostgreSQL URL), opened once.

    Parameters
    ----------
    db : str or Path
        ``condmon.db``, a path, or ``postgresql://user@host/db``.
    create : bool
        Make the database when it does not exist yet.

    Raises
    ------
    StoreError
        The database cannot be opened (naming it).
    """

    def __init__(self, db: str | Path = "condmon.db", *, create: bool = True) -> None:
        from condmon.store.db import open_store

        self.db = str(db)
        self.store: HistoryStore = open_store(self.db, create=create)

    def __enter__(self) -> History:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the database connection."""
        self.store.close()

    def __repr__(self) -> str:
        return f"History({self.db!r})"

    def _repr_html_(self) -> str:
        from condmon.report.notebook import html_table

        rows = [(u["unit"], u["model"], u["tests"], u["status"] or "—", u["summary"] or "")
                for u in self.store.unit_summaries()]
        return (f"<p>History <code>{self.db}</code>: {len(rows)} unit(s)</p>"
                + html_table(["unit", "model", "tests", "status", "summary"], rows))

    # -- records in ---------------------------------------------------------------------

    @one_blas_thread
    @_as_arguments
    def baseline_add(self, unit: str, records: Sequence[RecordLike] | RecordLike, *,
                     model: str | None = None, test_date: str | datetime | None = None,
                     group: str | None = None, options: EstimateOptions | None = None
                     ) -> BaselineAddResult:
        """Estimate healthy records and add them to the unit's baseline
        (``condmon baseline add``). ``records``: a list, or one record (a
        path, a DataFrame). ``model``: the unit's model at its first record
        (a shipped name or a declaration file); afterwards its own."""
        from condmon.io.columns import Columns

        one = isinstance(records, (str, Path, pd.DataFrame, Columns))
        opts = options or EstimateOptions(model=model)
        return add_baseline_tests(self.store, unit, [records] if one else list(records),  # type: ignore[list-item, arg-type]
                                  opts, test_date=test_date, group=group)

    @one_blas_thread
    @_as_arguments
    def check(self, unit: str, record: RecordLike, *, model: str | None = None,
              test_date: str | datetime | None = None, against: str | None = None,
              dry_run: bool = False, options: EstimateOptions | None = None) -> CheckResult:
        """Estimate a record, judge it against the unit's baseline (or another
        unit's or group's, ``against``) and store it (``condmon check``)."""
        opts = options or EstimateOptions(model=model)
        return check_test(self.store, unit, record, opts, test_date=test_date,
                          against=against, dry_run=dry_run)

    @one_blas_thread
    @_as_arguments
    def import_table(self, table: str | Path, model: str | Path, *, unit: str | None = None,
                     indicator: str | None = None, no_go: Sequence[str] = (),
                     baseline: int = 5) -> list[ImportedUnit]:
        """Store a table of already-measured indicator values as units' checks
        (``condmon import``, :func:`condmon.workflows.imports.import_table`)."""
        return import_table(self.store, table, model, unit=unit, indicator=indicator,
                            no_go=no_go, baseline_rows=baseline)

    # -- what the history holds ---------------------------------------------------------

    def history(self, unit: str) -> pd.DataFrame:
        """One row per test (``condmon history --json``): date, status, each
        parameter's value and standard error (``R``, ``R_se``)."""
        return self.store.history(unit)

    def units(self) -> pd.DataFrame:
        """One row per unit (``condmon units``): model, tests, status, summary."""
        return pd.DataFrame(self.store.unit_summaries())

    def audit(self, unit: str | None = None) -> pd.DataFrame:
        """The audit trail, oldest first (``condmon audit``)."""
        return self.store.audit(unit)

    @one_blas_thread
    @_as_arguments
    def forecast(self, unit: str, horizon: float | None = None) -> Forecast:
        """Each parameter's remaining life to no-go (``condmon forecast``).

        Raises
        ------
        DataError
            Fewer than 3 checks since the baseline.
        """
        from condmon.workflows.forecasting import forecast_unit

        return Forecast(forecast_unit(self.store, unit, horizon))

    def plot(self, unit: str) -> Any:
        """The unit's trend figure (as in its report): each check's change
        against the r1/r2 bands, with the forecast. A matplotlib Figure."""
        from condmon.report.notebook import unit_trend_figure

        return unit_trend_figure(self.store, unit)

    # -- looking after it ---------------------------------------------------------------

    @_as_arguments
    def exclude(self, test_id: int, reason: str) -> ChangeResult:
        """Exclude a wrong test (``condmon exclude``; kept, marked, audited)."""
        from condmon.workflows.manage import exclude_test

        return exclude_test(self.store, test_id, reason)

    @_as_arguments
    def include(self, test_id: int, reason: str | None = None) -> ChangeResult:
        """Include an excluded test again (``condmon include``)."""
        from condmon.workflows.manage import include_test

        return include_test(self.store, test_id, reason)

    @_as_arguments
    def set_model(self, unit: str, model: str, reason: str | None = None) -> ChangeResult:
        """Point a unit at its declaration file again (``condmon unit set-model``)."""
        from condmon.workflows.manage import set_unit_model

        return set_unit_model(self.store, unit, model, reason)


def load_model(model: str | Path) -> Machine:
    """A machine model: a shipped name (``dc-motor``, ``hst``) or a declaration file.

    Example
    -------
    >>> load_model("dc-motor").spec.unknowns
    ('R', 'L', 'Kt', 'J', 'D')
    """
    from condmon.models.registry import get_model

    return get_model(model)


def isolate(record: RecordLike, model: str | Path = "hst", **options: Any) -> IsolationResult:
    """Detect, estimate and isolate a parameter fault in one record of a
    plant model (``condmon isolate``): a file or a DataFrame with ``t`` and
    the model's sensor columns. ``options`` go to
    :func:`condmon.diagnose.isolation.isolate`.

    Example
    -------
    >>> from condmon.simulate.plant import simulate_plant
    >>> res = isolate(simulate_plant(load_model("hst").plant, ["Dm=-25%@10s"], seed=1))
    >>> res.isolated
    ('Dm',)
    """
    from condmon.diagnose.isolation import isolate as _isolate
    from condmon.io.records import read_record

    plant = load_model(model).plant
    frame = read_record(record) if isinstance(record, (str, Path)) else record
    source = str(record) if isinstance(record, (str, Path)) else "record"
    return _isolate(frame, plant, source=source, **options)


@one_blas_thread
@_as_arguments
def validate(record: RecordLike, model: str | Path, *, parameters: Any = None,
             values: Mapping[str, float] | None = None,
             initial: str | Mapping[str, float] = "estimated",
             columns: Mapping[str, str] | None = None,
             figure: str | Path | None = None) -> Comparison:
    """Simulate a model on a record's inputs and compare it with the record's
    outputs (``condmon validate``; MATLAB's ``compare``): the way a model is
    checked on data it was not fitted on.

    Parameters
    ----------
    record : str, Path or DataFrame
        The model's inputs and sensors (the declaration's ``[record]`` applies).
    model : str or Path
        A shipped model's name or a declaration file.
    parameters : EstimateResult, str, Path or mapping, optional
        An estimate of this model (its parameters and, from the simulation
        route, its initial states), the file ``condmon estimate --json``
        wrote, or ``{name: value}`` (as ``values``). Without it: the
        declaration's values.
    values : mapping of str to float, optional
        Parameter values over the estimate's and the declaration's. [SI]
    initial : str or mapping
        "estimated" (the estimate's initial states), "first-sample", "fit"
        (fitted on this record, the parameters fixed), or ``{state: value}``.
    columns : mapping of str to str, optional
        The model's names of the record's columns (``{"u": "uVal"}``), over
        the declaration's ``[record.columns]``.
    figure : str or Path, optional
        Where to write the measured-against-model figure (PNG).

    Returns
    -------
    Comparison
        ``rmse`` [sensor unit] and ``fit_percent`` [%] per output, the
        initial states used and where each came from, ``notes``.

    Example
    -------
    >>> import condmon
    >>> est = condmon.estimate(condmon.simulate_actuator(seed=1))
    >>> c = validate(condmon.simulate_actuator(seed=2), "dc-motor", parameters=est,
    ...              initial="first-sample")
    >>> {k: round(v) for k, v in c.fit_percent.items()}   # the sensors' noise bounds it
    {'I': 75, 'omega': 86}
    """
    from condmon.workflows.validation import validate_file

    import dataclasses

    doc = parameters.to_dict() if hasattr(parameters, "to_dict") else parameters
    if isinstance(doc, Mapping) and "parameters" not in doc:   # plain values, as values=
        values, doc = {**doc, **(values or {})}, None
    opts = EstimateOptions(model=str(model), columns=dict(columns) if columns else None)
    comparison, _ = validate_file(record, model, params=doc, set_values=values,
                                  initial=initial, figure=figure, options=opts)
    return dataclasses.replace(comparison,
                               notes=tuple(_python_text(n) for n in comparison.notes))
