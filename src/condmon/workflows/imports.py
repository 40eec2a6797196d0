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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from condmon.errors import CondmonError, ConfigError, DataError
from condmon.models.indicators import (
    IndicatorModel, load_indicators, override_end_of_life, parse_end_of_life, with_end_of_life,
)
from condmon.monitor.baseline import Baseline, make_baseline
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
    """

    unit: str
    added: int
    skipped: int
    baseline: int
    status: str
    axis: str
    end_of_life: dict[str, str]

    def to_dict(self) -> dict[str, Any]:
        return {"unit": self.unit, "added": self.added, "skipped": self.skipped,
                "baseline_rows": self.baseline, "status": self.status or None,
                "axis": self.axis, "end_of_life": self.end_of_life}


def _read(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(path)
        return pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except (OSError, ValueError, ImportError) as err:
        raise DataError(f"{path}: cannot be read as a table ({err}); nothing was stored"
                        ) from None


def _numbers(path: Path, df: pd.DataFrame, col: str, *, nonneg: bool = False) -> np.ndarray:
    """A column as float64, every cell a finite number (the first bad one named)."""
    raw = df[col]
    vals = pd.to_numeric(raw.astype(str).str.strip() if raw.dtype == object else raw,
                         errors="coerce").to_numpy(dtype=np.float64)
    bad = ~np.isfinite(vals) | ((vals < 0) if nonneg else False)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        shown = raw.iloc[i]
        what = "a negative standard error" if nonneg and np.isfinite(vals[i]) else \
            "empty" if str(shown).strip() == "" else "not a finite number"
        raise DataError(f"{path}: row {i + 1} (line {i + 2}), column {col!r}: {shown!r} is "
                        f"{what}; nothing was stored")
    return vals


def read_indicator_table(path: str | Path, model: IndicatorModel, unit: str | None = None,
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
    p = Path(path)
    df = _read(p)
    df.columns = [str(c).strip() for c in df.columns]
    axes = [a for a in AXES if a in df.columns]
    if not axes:
        raise DataError(f"{p}: no axis column; a table needs one of {', '.join(AXES)}")
    names = model.names
    if indicator is not None:
        model.indicator(indicator)
        units = [c for c in df.columns if c not in axes]
        if not units:
            raise DataError(f"{p}: no unit columns beside {', '.join(axes)}")
        long = df.melt(id_vars=axes, value_vars=units, var_name="unit", value_name=indicator)
        long["row"] = np.tile(np.arange(1, len(df) + 1), len(units))
        groups = {u: long[long["unit"] == u].drop(columns="unit") for u in units}
    else:
        allowed = [*axes, *names, *(f"{n}_se" for n in names)] + ([] if unit else ["unit"])
        unknown = [c for c in df.columns if c not in allowed]
        if unknown:
            raise DataError(f"{p}: column {unknown[0]!r} is not one of the declaration's "
                            f"indicators ({model.source or model.name}); the columns allowed "
                            f"are {', '.join(allowed)}")
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
        out[name] = _checked(p, g.reset_index(drop=True), axes, names)
    return out


def _checked(path: Path, g: pd.DataFrame, axes: list[str], names: Sequence[str]
             ) -> pd.DataFrame:
    rows = g["row"].to_numpy()
    out = pd.DataFrame({"row": rows})

    def at(i: int) -> str:
        return f"row {rows[i]} (line {rows[i] + 1})"

    for a in axes:
        if a == "date":
            raw = g[a].astype(str).str.strip()
            vals = pd.to_datetime(raw, utc=True, errors="coerce", format="mixed")
            bad = np.flatnonzero(vals.isna().to_numpy())
            if bad.size:
                raise DataError(f"{path}: {at(int(bad[0]))}, column 'date': "
                                f"{raw.iloc[int(bad[0])]!r} is not a date; nothing was stored")
            out[a] = vals.to_numpy()
            step = np.diff(vals.to_numpy().astype("datetime64[ns]").astype(np.int64))
        else:
            out[a] = _numbers(path, g, a)
            step = np.diff(out[a].to_numpy())
        back = np.flatnonzero(step <= 0)
        if back.size:
            i = int(back[0]) + 1
            raise DataError(f"{path}: {at(i)}, column {a!r}: {g[a].iloc[i]!s} is not after "
                            f"{g[a].iloc[i - 1]!s} ({at(i - 1)}); the {a} must increase down "
                            "the table; nothing was stored")
    for n in names:
        if n in g.columns:
            out[n] = _numbers(path, g, n)
            se = f"{n}_se"
            out[se] = _numbers(path, g, se, nonneg=True) if se in g.columns else np.nan
    return out


def _after_stored(store: HistoryStore, unit: str, first: pd.Series, axes: Sequence[str],
                  path: Path) -> None:
    """Refuse new rows that go back against the unit's stored tests."""
    hist = store.history(unit)
    for a, col in (("cycle", "cycle"), ("hours", "hours"), ("date", "test_date")):
        if a not in axes or col not in hist or not hist[col].notna().any():
            continue
        stored = hist[col].dropna().max()
        new = pd.Timestamp(first[a]) if a == "date" else float(first[a])
        if new <= stored:
            raise DataError(f"{path}: row {int(first['row'])} (line {int(first['row']) + 1}), "
                            f"column {a!r}: {first[a]!s} is not after the last one stored for "
                            f"unit {unit!r} ({stored!s}); the {a} must increase; nothing was "
                            "stored")


def _hash(unit: str, model: str, row: pd.Series, names: Sequence[str]) -> str:
    parts = [unit, model] + [f"{a}={row[a]}" for a in AXES if a in row.index] + [
        f"{n}={row[n]!r}" for n in names if n in row.index]
    return hashlib.sha256("|".join(map(str, parts)).encode("utf-8")).hexdigest()


def import_table(store: HistoryStore, path: str | Path, model_path: str | Path, *,
                 unit: str | None = None, indicator: str | None = None,
                 no_go: Sequence[str] = (), baseline_rows: int = DEFAULT_BASELINE_ROWS
                 ) -> list[ImportedUnit]:
    """Import a table's indicator values as its units' checks (see the module).

    Parameters
    ----------
    store : HistoryStore
    path : str or Path
        The table (``.csv``, or ``.parquet``).
    model_path : str or Path
        The indicator declaration (:mod:`condmon.models.indicators`).
    unit : str, optional
        The one unit the table holds.
    indicator : str, optional
        A table with a column per unit of this indicator.
    no_go : sequence of str
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
    if baseline_rows < 2:
        raise ConfigError(f"--baseline {baseline_rows}: a baseline needs 2 rows at least")
    model = load_indicators(model_path)
    own = dict(override_end_of_life(model, t) for t in no_go)
    tables = read_indicator_table(path, model, unit, indicator)
    source = str(Path(model_path).resolve())
    done = []
    for name, table in tables.items():
        done.append(_import_unit(store, name, table, model, own, source, Path(path),
                                 baseline_rows))
    return done


def _import_unit(store: HistoryStore, unit: str, table: pd.DataFrame, model: IndicatorModel,
                 own: dict[str, Any], source: str, path: Path, baseline_rows: int
                 ) -> ImportedUnit:
    stored_own = {}
    try:
        stored_own = store.end_of_life(unit)
    except CondmonError:
        pass
    mine = with_end_of_life(model, {**{k: parse_end_of_life(v, k, model.indicator(k).unit,
                                                            model.indicator(k).rated)
                                       for k, v in stored_own.items() if k in model.names},
                                    **own})
    names = [n for n in model.names if n in table.columns]
    seen = store.imported_hashes(unit)
    hashes = [_hash(unit, model.name, r, names) for _, r in table.iterrows()]
    fresh = [i for i, h in enumerate(hashes) if h not in seen]
    axes = [a for a in AXES if a in table.columns]
    eol = {i.name: i.end_of_life.text for i in mine.indicators}
    if not fresh:
        return ImportedUnit(unit, 0, len(table), 0, "", ", ".join(axes), eol)
    if seen:
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
        new_base = make_baseline([{n: float(r[n]) for n in names} for _, r in first.iterrows()])
        base, baseline_id = new_base, None
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
    store.add_imported(unit, model.name, source, tests, baseline=new_base,
                       baseline_id=baseline_id,
                       end_of_life={k: v.text for k, v in own.items()} or None)
    return ImportedUnit(unit, len(fresh), len(table) - len(fresh), n_base, last,
                        ", ".join(axes), eol)
