"""``condmon import``: already-measured indicator values stored as a unit's checks.

A table (CSV, or Parquet) holds one indicator value per row and column: a
battery's capacity per cycle, a resistance from an impedance test, a value
from another system. Its columns:

- the axis: ``cycle``, ``hours`` (operating hours) or ``date``; at least one,
  increasing down the table for each unit;
- each indicator the declaration names (``capacity``), and optionally its
  standard error (``capacity_se``), in the declaration's unit;
- the unit: ``--unit NAME`` for a table of one unit, or a ``unit`` column
  (a unit per row), or, with ``--indicator NAME``, a column per unit of that
  one indicator.

Every cell is checked before anything is stored; a bad one is refused with
its row and column named, and nothing is stored. A unit's first rows make
its baseline when it has none (``baseline`` rows, 5 by default); the later
rows are checks judged against it (:mod:`condmon.monitor.indicators`).
Rows already in the history are not stored again, so a table that grew can
be imported again.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from condmon.errors import CondmonError, ConfigError, DataError
from condmon.models.indicators import (
    IndicatorModel, load_indicators, override_end_of_life, with_end_of_life,
    with_own_end_of_life,
)
from condmon.monitor.baseline import MIN_BASELINE_TESTS, Baseline, make_baseline
from condmon.monitor.indicators import judge_indicators
from condmon.store.baselines import current_baseline
from condmon.store.db import HistoryStore
from condmon.store.imports import ImportedTest

__all__ = ["AXES", "ImportedUnit", "read_indicator_table", "import_table", "DEFAULT_BASELINE_ROWS"]

#: The axis columns a table may hold.
AXES = ("cycle", "hours", "date")
#: Rows that make a new unit's baseline, unless told otherwise.
DEFAULT_BASELINE_ROWS = 5


@dataclass(frozen=True)
class ImportedUnit:
    """What one unit's import stored.

    Attributes
    ----------
    unit : str
    added, skipped : int
        Rows stored, and rows already in the history.
    baseline : int
        Rows that made a new baseline (0: the unit's stored one was used).
    status : str
        The last stored check's status ("" when none was stored).
    axis : str
        The table's axis columns, as stored.
    end_of_life : dict of str to str
        Each indicator's end of life for this unit.
    changed : tuple of str
        What ``--no-go`` changed of the unit's end of life (from, to), a line each.
    """

    unit: str
    added: int
    skipped: int
    baseline: int
    status: str
    axis: str
    end_of_life: dict[str, str]
    changed: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"unit": self.unit, "added": self.added, "skipped": self.skipped,
                "baseline_rows": self.baseline, "status": self.status or None,
                "axis": self.axis, "end_of_life": self.end_of_life,
                "end_of_life_changed": list(self.changed)}


#: The largest magnitude a value may have (as records'). [-]
_HUGE = 1e15


def _read(path: Path) -> pd.DataFrame:
    if path.is_dir():
        raise DataError(f"{path}: a folder, not a table")
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(path)
        with path.open("r", encoding="utf-8-sig", errors="replace") as fh:
            header = fh.readline()
        # a table written with ';' between cells (and ',' for the decimal point)
        semi = ";" in header and "," not in header
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True,
                         sep=";" if semi else ",", encoding="utf-8-sig")
        df.attrs["separator"] = ";" if semi else ","
        return df
    except (OSError, ValueError, ImportError) as err:
        why = " ".join(str(err).split())
        raise DataError(f"{path}: cannot be read as a table ({why}); nothing was stored"
                        ) from None


def _decimal_commas(path: Path, df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with each decimal comma of its text columns read as a point.

    A comma is a decimal mark only in a column none of whose cells has a
    point, of a table not separated by commas ("1,856" in a table of ';').
    Otherwise ("1,750" quoted in a table of ',', or beside "1.85") it may as
    well separate thousands: the first such cell is refused, not guessed."""
    comma_table = df.attrs.get("separator") == ","
    for col in df.columns:
        if col in ("unit", "date") or pd.api.types.is_numeric_dtype(df[col]):
            continue
        text = df[col].astype(str)
        commas = text.str.contains(",", regex=False).to_numpy()
        if not commas.any():
            continue
        i = int(np.flatnonzero(commas)[0])
        dotted = text.str.contains(".", regex=False).to_numpy()
        if comma_table or dotted.any():
            why = ("the table's cells are separated by commas" if comma_table else
                   f"row {int(np.flatnonzero(dotted)[0]) + 1} of the column has a decimal point")
            raise DataError(f"{path}: row {i + 1} (line {i + 2}), column {col!r}: "
                            f"{text.iloc[i]!r} has a comma, and {why}: a thousands separator "
                            "or a decimal comma? write the number without it; nothing was "
                            "stored")
        df[col] = text.str.replace(",", ".", regex=False)
    return df


def _numbers(path: Path, df: pd.DataFrame, col: str, *, nonneg: bool = False,
             label: str | None = None) -> np.ndarray:
    """A column as float64, every cell a finite number of sane size (the first
    bad one named by the table's row, and by ``label``, the file's name of the
    column, when it has another)."""
    raw = df[col]
    text = raw if pd.api.types.is_numeric_dtype(raw) else raw.astype(str).str.strip()
    vals = pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(vals) | (np.abs(vals) > _HUGE) | ((vals < 0) if nonneg else False)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        shown = raw.iloc[i]
        if isinstance(shown, (float, np.floating)):   # not numpy's repr: np.float64(nan)
            shown = "" if math.isnan(shown) else float(shown)
        what = "a negative standard error" if nonneg and np.isfinite(vals[i]) and vals[i] < 0 \
            else "empty" if str(shown).strip() == "" else \
            f"beyond {_HUGE:.0e}" if np.isfinite(vals[i]) else "not a finite number"
        row = int(df["row"].iloc[i]) if "row" in df else i + 1
        raise DataError(f"{path}: row {row} (line {row + 1}), column {(label or col)!r}: "
                        f"{shown!r} is {what}; nothing was stored")
    return vals


def read_indicator_table(path: str | Path | pd.DataFrame, model: IndicatorModel,
                         unit: str | None = None,
                         indicator: str | None = None) -> dict[str, pd.DataFrame]:
    """A table's rows per unit, checked (see the module).

    Returns
    -------
    dict of str to DataFrame
        Per unit, in table order: the axis columns present (``cycle`` and
        ``hours`` float, ``date`` UTC), each indicator and ``<indicator>_se``
        (NaN: none given), and ``row`` (the table's row, from 1).

    Raises
    ------
    DataError
        An unreadable table, an unknown column (the allowed ones named), a
        cell that is not a finite number, an axis that does not increase
        (the row and column named).
    ConfigError
        ``indicator`` not declared.
    """
    if isinstance(path, pd.DataFrame):
        p, df = Path("table"), path.copy()
    else:
        p = Path(path)
        df = _read(p)
    df.columns = [str(c).strip() for c in df.columns]
    if not len(df):
        raise DataError(f"{p}: no rows under the header; nothing was stored")
    df = _decimal_commas(p, df)
    axes = [a for a in AXES if a in df.columns]
    names = model.names
    if not axes:
        near = [c for c in df.columns if c.lower() in (*AXES, *names)]
        hint = (f" (names are case-sensitive: {', '.join(repr(c) for c in near)})" if near
                else "")
        raise DataError(f"{p}: no axis column; a table needs one of {', '.join(AXES)}, and "
                        f"has {', '.join(repr(c) for c in df.columns)}{hint}")
    if indicator is not None:
        model.indicator(indicator)
        if unit is not None:
            raise DataError(f"{p}: --unit {unit} with --indicator {indicator}: a table of a "
                            "column per unit names its units by its columns "
                            f"({', '.join(repr(c) for c in df.columns if c not in axes)}); "
                            "omit --unit")
        clash = [c for c in df.columns if c in (*names, "unit")]
        if clash:
            raise DataError(f"{p}: column {clash[0]!r} in a table of a column per unit "
                            f"(--indicator {indicator}): name each column by its unit")
        units = [c for c in df.columns if c not in axes]
        if not units:
            raise DataError(f"{p}: no unit columns beside {', '.join(axes)}")
        long = df.melt(id_vars=axes, value_vars=units, var_name="unit", value_name=indicator)
        long["row"] = np.tile(np.arange(1, len(df) + 1), len(units))
        # an empty cell is no reading of that unit there: units run to different
        # lengths (a cell that failed early), and a cycle may go unmeasured
        cell = long[indicator]
        blank = cell.isna() | (cell.astype(str).str.strip() == "")
        long = long[~blank.to_numpy()]
        groups = {u: long[long["unit"] == u].drop(columns="unit") for u in units}
        for u, g in groups.items():
            if not len(g):
                raise DataError(f"{p}: column {u!r} has no reading; nothing was stored")
    else:
        if unit is not None and "unit" in df.columns:
            raise DataError(f"{p}: the table has a 'unit' column; omit --unit {unit} (each "
                            "row names its unit)")
        allowed = [*axes, *names, *(f"{n}_se" for n in names)] + ([] if unit else ["unit"])
        unknown = [c for c in df.columns if c not in allowed]
        if unknown:
            wide = (" (a column per unit? give --indicator NAME)"
                    if len(model.names) == 1 and not any(n in df.columns for n in names) else "")
            raise DataError(f"{p}: column {unknown[0]!r} is not one of the declaration's "
                            f"indicators ({model.source or model.name}); the columns allowed "
                            f"are {', '.join(allowed)}{wide}")
        if not any(n in df.columns for n in names):
            raise DataError(f"{p}: no indicator column; the declaration names "
                            f"{', '.join(names)}")
        df = df.assign(row=np.arange(1, len(df) + 1))
        if unit is not None:
            groups = {unit: df}
        elif "unit" in df.columns:
            groups = {str(u).strip(): g for u, g in df.groupby(df["unit"].astype(str).str.strip(),
                                                                 sort=False)}
            groups = {u: g.drop(columns="unit") for u, g in groups.items()}
        else:
            raise DataError(f"{p}: which unit? give --unit NAME, or a 'unit' column")
    out = {}
    for name, g in groups.items():
        if not name:
            raise DataError(f"{p}: row {int(g['row'].iloc[0])}: the unit is empty")
        out[name] = _checked(p, g.reset_index(drop=True), axes, names,
                             {indicator: name} if indicator is not None else {})
    return out


def _checked(path: Path, g: pd.DataFrame, axes: list[str], names: Sequence[str],
             labels: Mapping[str, str] | None = None) -> pd.DataFrame:
    rows = g["row"].to_numpy()
    out = pd.DataFrame({"row": rows})

    def at(i: int) -> str:
        return f"row {rows[i]} (line {rows[i] + 1})"

    for a in axes:
        if a == "date":
            raw = g[a].astype(str).str.strip()
            # ISO 8601 only: 01/02/2024 is the 2nd of January in one country, the
            # 1st of February in another
            vals = pd.to_datetime(raw, utc=True, errors="coerce", format="ISO8601")
            bad = np.flatnonzero(vals.isna().to_numpy())
            if bad.size:
                raise DataError(f"{path}: {at(int(bad[0]))}, column 'date': "
                                f"{raw.iloc[int(bad[0])]!r} is not an ISO 8601 date "
                                "(2024-01-12, or 2024-01-12T08:30); nothing was stored")
            ahead = np.flatnonzero((vals > pd.Timestamp.now(tz="UTC") + pd.Timedelta(days=1))
                                   .to_numpy())   # (as `check --date` refuses)
            if ahead.size:
                raise DataError(f"{path}: {at(int(ahead[0]))}, column 'date': "
                                f"{raw.iloc[int(ahead[0])]!r} is more than a day in the future; "
                                "give the date the value was measured; nothing was stored")
            out[a] = vals.to_numpy()
            step = np.diff((vals - vals.iloc[0]).dt.total_seconds().to_numpy())
        else:
            out[a] = _numbers(path, g, a)
            step = np.diff(out[a].to_numpy())
        # a date beside a cycle or hours column only dates the rows they order:
        # a cycler runs several cycles a day
        beside = a == "date" and len(axes) > 1
        back = np.flatnonzero(step < 0 if beside else step <= 0)
        if back.size:
            i = int(back[0]) + 1
            raise DataError(f"{path}: {at(i)}, column {a!r}: {g[a].iloc[i]!s} is "
                            f"{'before' if beside else 'not after'} {g[a].iloc[i - 1]!s} "
                            f"({at(i - 1)}); the {a} must "
                            f"{'not go back' if beside else 'increase'} down the table; "
                            "nothing was stored")
    for n in names:
        if n in g.columns:
            out[n] = _numbers(path, g, n, label=(labels or {}).get(n))
            se = f"{n}_se"
            out[se] = _numbers(path, g, se, nonneg=True) if se in g.columns else np.nan
    return out


def _same_declaration(store: HistoryStore, unit: str, model: IndicatorModel) -> None:
    """Refuse another declaration of the same name for a unit (its end of
    life or units differ): as a record offered with another model is."""
    from condmon.store.declarations import bundle_digest

    source, kept = store.unit_declaration(unit)
    new = bundle_digest(model.source) if model.source else None
    if kept is not None and new is not None and new != kept:
        raise DataError(f"unit {unit!r} is monitored with {source!r}; {model.source!r} is "
                        f"another declaration of {model.name!r} (its indicators, units or end "
                        f"of life differ): import with the unit's own, or `condmon unit "
                        f"set-model {unit} FILE` to re-point it on purpose; nothing was stored")


def _after_stored(store: HistoryStore, unit: str, first: pd.Series, axes: Sequence[str],
                  path: Path) -> None:
    """Refuse new rows that go back against the unit's stored tests, or that
    lack the axis its stored tests are counted on."""
    hist = store.history(unit)
    for a, col in (("cycle", "cycle"), ("hours", "hours")):
        if col in hist and hist[col].notna().any() and a not in axes:
            raise DataError(f"{path}: unit {unit!r} is counted in {a} (its stored tests have "
                            f"a {a}), and this table has no {a!r} column; nothing was stored")
    for a, col in (("cycle", "cycle"), ("hours", "hours"), ("date", "test_date")):
        if a not in axes or col not in hist or not hist[col].notna().any():
            continue
        if a == "date" and len(axes) > 1:   # dates the rows the other axis orders
            continue
        stored = hist[col].dropna().max()
        new = pd.Timestamp(first[a]) if a == "date" else float(first[a])
        same = hist[hist[col] == new]
        if len(same):   # a row of a stored test whose values differ: an edited table
            raise DataError(f"{path}: row {int(first['row'])} (line {int(first['row']) + 1}): "
                            f"{a} {first[a]!s} of unit {unit!r} is stored already (test "
                            f"#{int(same.index[0])}) with other values: a row edited since "
                            "it was imported? Stored tests are not overwritten; nothing was "
                            "stored")
        if new <= stored:
            raise DataError(f"{path}: row {int(first['row'])} (line {int(first['row']) + 1}), "
                            f"column {a!r}: {first[a]!s} is not after the last one stored for "
                            f"unit {unit!r} ({stored!s}); the {a} must increase; nothing was "
                            "stored")


def _hash(unit: str, model: str, row: pd.Series, names: Sequence[str]) -> str:
    parts = [unit, model] + [f"{a}={row[a]}" for a in AXES if a in row.index] + [
        f"{n}={row[n]!r}" for n in names if n in row.index]
    return hashlib.sha256("|".join(map(str, parts)).encode("utf-8")).hexdigest()


def import_table(store: HistoryStore, path: str | Path | pd.DataFrame,
                 model_path: str | Path, *, unit: str | None = None,
                 indicator: str | None = None, no_go: str | Sequence[str] = (),
                 baseline_rows: int = DEFAULT_BASELINE_ROWS) -> list[ImportedUnit]:
    """Import a table's indicator values as its units' checks (see the module).

    Parameters
    ----------
    store : HistoryStore
    path : str, Path or DataFrame
        The table (``.csv``, or ``.parquet``), or a frame of its columns.
    model_path : str or Path
        The indicator declaration (:mod:`condmon.models.indicators`).
    unit : str, optional
        The one unit the table holds.
    indicator : str, optional
        A table with a column per unit of this indicator.
    no_go : str or sequence of str
        The units' own end of life, ``"capacity<0.88"`` (kept for them).
    baseline_rows : int
        Rows that make a new unit's baseline (at least 2).

    Returns
    -------
    list of ImportedUnit

    Raises
    ------
    DataError, ConfigError
        A bad table, declaration or end of life: nothing is stored.

    Example
    -------
    >>> import tempfile, pathlib
    >>> from condmon.store import open_store
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "cell.toml").write_text('name = "cell"\\n[indicators]\\n'
    ...     'capacity = { unit = "Ah", end_of_life = "< 1.4 Ah" }\\n')
    >>> _ = (d / "c1.csv").write_text("cycle,capacity\\n" + "".join(
    ...     f"{k},{2.0 - 0.004 * k + 0.002 * (-1) ** k}\\n" for k in range(1, 41)))
    >>> with open_store("sqlite://") as store:
    ...     [u.added for u in import_table(store, d / "c1.csv", d / "cell.toml", unit="C1")]
    [40]
    """
    if baseline_rows < MIN_BASELINE_TESTS:
        raise ConfigError(f"--baseline {baseline_rows}: a baseline needs "
                          f"{MIN_BASELINE_TESTS} rows at least")
    model = load_indicators(model_path)
    own = dict(override_end_of_life(model, t) for t in ([no_go] if isinstance(no_go, str)
                                                         else no_go))
    tables = read_indicator_table(path, model, unit, indicator)
    source = str(Path(model_path).resolve())
    where = Path("table") if isinstance(path, pd.DataFrame) else Path(path)
    # every unit's rows are checked before any is stored
    plans = [_plan_unit(store, name, table, model, own, where, baseline_rows)
             for name, table in tables.items()]
    return [_store_unit(store, plan, model, own, source) for plan in plans]


#: The largest believable change of an imported value from its unit's
#: baseline, times or divided by (a "likely unit or sign error" beyond, as
#: ``[estimation.max_change]`` of a declaration whose parameters are estimated).
#: The band is widened to take in the declared end of life: a unit heading for
#: it is believable on its way and a little past it (a 12 mm pad worn to its
#: 3 mm limit, a bearing from 2 mm/s towards its 7.1 mm/s trip).
MAX_CHANGE = 3.0

#: How far a new baseline's mean may lie from a declared absolute end-of-life
#: level, times or divided by: two decades. A healthy unit and its end of life
#: can be far apart (a crack from 0.1 mm to 10 mm; ISO 10816's vibration zones
#: from 0.28 to 4.5 mm/s), a unit prefix (milli, kilo) is a thousand. Against a
#: declared rated value the band is :data:`MAX_CHANGE`: a new unit is near it.
LEVEL_SPAN = 100.0


@dataclass(frozen=True)
class _Plan:
    """One unit's rows, checked and judged, ready to store."""

    unit: str
    tests: list[ImportedTest]
    base: Baseline | None
    baseline_id: int | None
    n_base: int
    skipped: int
    status: str
    axis: str
    eol: dict[str, str]
    own: dict[str, str]           # the unit's own end of life to keep, as written
    changed: tuple[str, ...]      # what --no-go changed of it


def _plan_unit(store: HistoryStore, unit: str, table: pd.DataFrame, model: IndicatorModel,
               own: dict[str, Any], path: Path, baseline_rows: int) -> _Plan:
    stored = store.end_of_life(unit)
    before = with_own_end_of_life(model, stored, f"unit {unit!r}")
    mine = with_end_of_life(before, own)
    # --no-go adds to the unit's own end of life, indicator by indicator; a change
    # of a stored unit's is said, with what the rows stored before keep
    keep = {**stored, **{k: v.text for k, v in own.items()}}
    changed = tuple(
        f"{k}: end of life changed from {_eol_text(before.indicator(k))} to "
        f"{_eol_text(mine.indicator(k))}; the checks stored before keep the status they "
        "were judged with, the forecast uses the new one"
        for k in own if before.indicator(k).end_of_life.text != own[k].text) \
        if unit in store.units() else ()
    names = [n for n in model.names if n in table.columns]
    seen = store.imported_hashes(unit)
    hashes = [_hash(unit, model.name, r, names) for _, r in table.iterrows()]
    fresh = [i for i, h in enumerate(hashes) if h not in seen]
    axes = [a for a in AXES if a in table.columns]
    eol = {i.name: _eol_text(i) for i in mine.indicators}
    if not fresh:
        return _Plan(unit, [], None, None, 0, len(table), "", ", ".join(axes), eol, keep,
                     changed)
    if seen:   # (another declaration first: its rows hash apart, so all look new)
        _same_declaration(store, unit, model)
        _after_stored(store, unit, table.iloc[fresh[0]], axes, path)
    try:
        base, _ = current_baseline(store, unit)
        latest = store.latest_baseline(unit)
        baseline_id = None if latest is None else latest.id
        new_base: Baseline | None = None
        n_base = 0
    except CondmonError:   # no baseline yet: the first rows make it
        if len(fresh) < baseline_rows + 1:
            raise DataError(f"{path}: unit {unit!r} has no baseline, and {len(fresh)} new "
                            f"row(s) cannot make one of {baseline_rows} and leave a check; "
                            "nothing was stored") from None
        n_base = baseline_rows
        first = table.iloc[fresh[:n_base]]
        for n in names:
            if float(first[n].mean()) == 0.0:
                raise DataError(f"{path}: rows {int(first['row'].iloc[0])}-"
                                f"{int(first['row'].iloc[-1])} (the baseline of unit {unit!r}), "
                                f"column {n!r}: their mean is 0, so a change from it is "
                                "undefined; nothing was stored")
        for ind in mine.indicators:
            if ind.name in names:
                _near_its_declared_size(path, unit, first, ind)
        new_base = make_baseline([{n: float(r[n]) for n in names} for _, r in first.iterrows()])
        base, baseline_id = new_base, None
    for ind in mine.indicators:
        if ind.name in names and ind.name in base.parameters:
            _believable(path, unit, table.iloc[fresh], ind, base)
    tests = []
    last = ""
    for k, i in enumerate(fresh):
        r = table.iloc[i]
        values = {n: (float(r[n]), None if math.isnan(r[f"{n}_se"]) else float(r[f"{n}_se"]))
                  for n in names}
        role = "baseline" if k < n_base else "check"
        judged = None
        if role == "check":
            judged = judge_indicators({n: v for n, (v, _) in values.items()},
                                      {n: se or 0.0 for n, (_, se) in values.items()},
                                      mine.indicators, base)
            last = judged.status
        tests.append(ImportedTest(
            f"{path.name}:row {int(r['row'])}", hashes[i], values, role,
            float(r["cycle"]) if "cycle" in r.index else None,
            float(r["hours"]) if "hours" in r.index else None,
            pd.Timestamp(r["date"]).to_pydatetime() if "date" in r.index else None, judged))
    return _Plan(unit, tests, new_base, baseline_id, n_base, len(table) - len(fresh), last,
                 ", ".join(axes), eol, keep, changed)


def _eol_text(ind: Any) -> str:
    """An indicator's end of life as a user reads it, with its unit (``< 1.4 Ah``)."""
    text = re.sub(r"^\s*([<>]=?)\s*", r"\1 ", str(ind.end_of_life.text))   # "<5" as "< 5"
    return text + (f" {ind.unit}" if ind.end_of_life.kind == "level"
                   and not text.rstrip().endswith(ind.unit) else "")


def _near_its_declared_size(path: Path, unit: str, first: pd.DataFrame, ind: Any) -> None:
    """Refuse a new baseline whose mean is beyond :data:`MAX_CHANGE` times (or
    a fraction) of the declared rated value or absolute end-of-life level:
    values in another unit (mAh for a declared Ah) would else be trended,
    judged against a level a thousand times off and forecast."""
    mean = float(first[ind.name].mean())
    sizes = [("rated value", ind.rated, MAX_CHANGE)] if ind.rated else []
    if ind.end_of_life is not None and ind.end_of_life.kind == "level":
        sizes.append(("end-of-life level", ind.end_of_life.value, LEVEL_SPAN))
    for what, size, factor in sizes:
        ratio = mean / size if size else math.nan
        if 1.0 / factor <= ratio <= factor:
            continue
        raise DataError(f"{path}: rows {int(first['row'].iloc[0])}-{int(first['row'].iloc[-1])} "
                        f"(the baseline of unit {unit!r}), column {ind.name!r}: their mean "
                        f"{mean:.4g} is {ratio:.3g} times the declared {what} "
                        f"({size:g} {ind.unit}); values in another unit than {ind.unit}? "
                        f"(more than {factor:g}x either way is refused); nothing was stored")


def _believable(path: Path, unit: str, rows: pd.DataFrame, ind: Any, base: Baseline) -> None:
    """Refuse rows whose value cannot be the unit's: its sign flipped, or more
    than :data:`MAX_CHANGE` times beyond the span from the baseline mean to the
    end of life (a unit or sign error, a missing reading written as 0); and an
    end of life the baseline is already past."""
    mean = float(base.mean[base.parameters.index(ind.name)])
    level = ind.end_of_life.level(mean, ind.rated)
    if ind.end_of_life.reached(mean, mean, ind.rated):
        raise DataError(f"{path}: unit {unit!r}: its baseline {ind.name} {mean:.4g} {ind.unit} "
                        f"is already past its end of life ({ind.end_of_life.text}, "
                        f"{level:.4g} {ind.unit}): check the end of life's direction and "
                        "level; nothing was stored")
    v = rows[ind.name].to_numpy(dtype=np.float64)
    # the band: MAX_CHANGE times beyond the span from the baseline to the end of life
    # (a level of the baseline's sign; else the baseline alone)
    ends = [mean, level] if level * mean > 0 else [mean]
    lo, hi = min(map(abs, ends)) / MAX_CHANGE, max(map(abs, ends)) * MAX_CHANGE
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = v / mean
    odd = np.flatnonzero((ratio <= 0) | (np.abs(v) > hi) | (np.abs(v) < lo))
    if odd.size:
        i = int(odd[0])
        row = int(rows["row"].iloc[i])
        span = (f"{MAX_CHANGE:g}x beyond its baseline ({mean:.4g} {ind.unit}) and its end of "
                f"life ({level:.4g} {ind.unit})" if len(ends) == 2 else
                f"{MAX_CHANGE:g}x its baseline ({mean:.4g} {ind.unit})")
        why = ("of the other sign than its baseline, or 0: a sign error or a missing "
               "reading" if ratio[i] <= 0 else f"{ratio[i]:.3g} times its baseline mean, "
               f"more than {span}: likely a unit error")
        raise DataError(f"{path}: row {row} (line {row + 1}), column {ind.name!r}: {v[i]:g} is "
                        f"{why}; nothing was stored")


def _store_unit(store: HistoryStore, plan: _Plan, model: IndicatorModel,
                own: dict[str, Any], source: str) -> ImportedUnit:
    if plan.tests or plan.changed:   # (no new rows: the unit's end of life still kept)
        store.add_imported(plan.unit, model.name, source, plan.tests, baseline=plan.base,
                           baseline_id=plan.baseline_id, end_of_life=plan.own or None)
    return ImportedUnit(plan.unit, len(plan.tests), plan.skipped, plan.n_base, plan.status,
                        plan.axis, plan.eol, plan.changed)
