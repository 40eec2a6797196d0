"""How a rig writes its records: the ``[record]`` settings, applied once at the boundary.

A rig's raw files rarely hold SI columns under the model's names: a data
logger writes a sample counter instead of seconds, ADC counts instead of
pascals, and columns of its own beside the signals. A ``[record]`` table (in a
machine's declaration, a unit folder's ``unit.toml``, a manifest row) or the
matching command-line options say how to read them:

.. code-block:: toml

    [record]
    sample_rate = 250.0                 # [Hz]: t counts samples (or is absent)
    ignore = ["F_Names", "F_Values"]    # file columns dropped on reading
    name_time = "%m-%d-%Y-%I-%M-%S %p"  # the start time, as the file names write it
    [record.columns]                    # model name = file column, or a table
    theta = { column = "Angle", scale = 3.835e-4, offset = 0.0 }   # counts -> rad
    pA = { column = "PG_1", scale = 1262.5 }                         # counts -> Pa
    t = "Time"

:func:`apply_record_settings` turns a frame as read into the frame every later
stage expects: ignored columns dropped, columns renamed to the model's names,
each scaled (``value = raw * scale + offset``) and, with a sample rate, ``t``
in seconds from the first sample. Settings from several places are merged with
:meth:`RecordSettings.merged`, the later one winning key by key (declaration <
``unit.toml`` < manifest row < command line).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.errors import ConfigError, DataError, DataWarning
from condmon.io.dates import name_time_format, time_in_name

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["RecordSettings", "parse_record_settings", "apply_record_settings", "rig_layout",
           "parse_assignments", "settings_from_options", "RECORD_KEYS"]

#: Keys a ``[record]`` table may hold.
RECORD_KEYS = ("columns", "sample_rate", "scale", "offset", "ignore", "name_time")


@dataclass(frozen=True)
class RecordSettings:
    """How to read a rig's files (see the module's description).

    Attributes
    ----------
    columns : dict of str to str
        ``{model name: file column}``. A file column that already carries a
        model name needs no entry.
    sample_rate : float or None
        Samples per second when ``t`` counts samples or is absent; None: ``t``
        is in seconds. [Hz]
    scale : dict of str to float
        Factor per model column: ``value = raw * scale + offset``. [unit/raw]
    offset : dict of str to float
        Offset per model column, added after the scale. [unit]
    ignore : tuple of str
        File columns dropped on reading (a logger's own columns).
    accuracy : dict of str to float
        Stated accuracy of a model column's sensor, as a bound on its error
        in the column's unit after scaling (``accuracy = 51711.0``, or
        ``accuracy = "0.25 %"`` of ``full_scale``); the estimate's systematic
        part comes from it (:func:`condmon.identify.estimate.systematic_part`). [unit]
    sources : tuple of str
        Where the settings came from, for messages and notes.
    name_time : str or None
        The ``strptime`` format in which the rig writes each record's start
        time into its file name (``"%m-%d-%Y-%I-%M-%S %p"``); the test's date
        when no other is given (:func:`condmon.io.dates.time_in_name`).

    Example
    -------
    >>> s = RecordSettings(columns={"t": "Time"}, sample_rate=100.0)
    >>> import pandas as pd
    >>> df = apply_record_settings(pd.DataFrame({"Time": [1, 2, 3]}), s)
    >>> df["t"].tolist()
    [0.0, 0.01, 0.02]
    """

    columns: dict[str, str] = field(default_factory=dict)
    sample_rate: float | None = None
    scale: dict[str, float] = field(default_factory=dict)
    offset: dict[str, float] = field(default_factory=dict)
    ignore: tuple[str, ...] = ()
    sources: tuple[str, ...] = ()
    accuracy: dict[str, float] = field(default_factory=dict)
    name_time: str | None = None

    @property
    def empty(self) -> bool:
        """Whether the settings change nothing."""
        return not (self.columns or self.sample_rate is not None or self.scale
                    or self.offset or self.ignore or self.name_time)

    def merged(self, later: RecordSettings | None) -> RecordSettings:
        """These settings with ``later`` ones winning key by key.

        Example
        -------
        >>> a = RecordSettings(columns={"V": "volts"}, scale={"V": 2.0})
        >>> b = RecordSettings(scale={"V": 3.0}, sample_rate=10.0)
        >>> m = a.merged(b)
        >>> m.columns, m.scale, m.sample_rate
        ({'V': 'volts'}, {'V': 3.0}, 10.0)
        >>> b.merged(RecordSettings(columns={"t": "seconds"})).sample_rate is None
        True
        """
        if later is None or later.empty:
            return self if not (later and later.sources) else replace(
                self, sources=(*self.sources, *later.sources))
        # a column mapped to another file column takes that column's own scale,
        # offset, accuracy (and, for t, sample rate): none of the earlier ones
        moved = {k for k, v in later.columns.items() if self.columns.get(k, k) != v}

        def kept(table: Mapping[str, Any]) -> dict[str, Any]:
            return {k: v for k, v in table.items() if k not in moved}

        rate = later.sample_rate if later.sample_rate is not None else (
            None if "t" in moved else self.sample_rate)
        return RecordSettings(
            {**self.columns, **later.columns}, rate,
            {**kept(self.scale), **later.scale}, {**kept(self.offset), **later.offset},
            tuple(dict.fromkeys((*self.ignore, *later.ignore))),
            tuple(dict.fromkeys((*self.sources, *later.sources))),
            {**kept(self.accuracy), **later.accuracy}, later.name_time or self.name_time)

    def describe(self, dropped: int | None = None) -> str:
        """One line saying what the settings do (for notes); ``dropped``: how
        many of the ignored columns a record had (default: as many as named)."""
        parts = []
        if self.columns:
            parts.append("columns " + ", ".join(f"{k}={v}" for k, v in self.columns.items()))
        if self.sample_rate is not None:
            parts.append(f"sample rate {self.sample_rate:g} Hz")
        scaled = sorted(set(self.scale) | set(self.offset))
        if scaled:
            parts.append("scaled " + ", ".join(scaled))
        n = len(self.ignore) if dropped is None else dropped
        if n:
            parts.append(f"{n} column(s) ignored")
        return "; ".join(parts) or "as written"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"columns": dict(self.columns), "sample_rate": self.sample_rate,
                "scale": dict(self.scale), "offset": dict(self.offset),
                "ignore": list(self.ignore), "sources": list(self.sources),
                "accuracy": dict(self.accuracy), "name_time": self.name_time}


def _finite(value: Any, where: str, *, nonzero: bool = False, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            value = float(str(value).strip())
        except ValueError:
            raise ConfigError(f"{where} must be a number, not {value!r}") from None
    out = float(value)
    if not math.isfinite(out):
        raise ConfigError(f"{where} must be a finite number, not {value!r}")
    if positive and not out > 0:
        raise ConfigError(f"{where} must be > 0, not {value!r}")
    if nonzero and out == 0:
        raise ConfigError(f"{where} must not be 0 (it would erase the column)")
    return out


#: Keys of a ``[record.columns]`` entry given as a table.
_COLUMN_KEYS = ("column", "scale", "offset", "unit", "accuracy", "full_scale")


def _accuracy(spec: Mapping[str, Any], here: str) -> float:
    """A column's stated accuracy in its unit: a number, or ``"X %"`` of ``full_scale``.

    Example
    -------
    >>> _accuracy({"accuracy": "0.25 %", "full_scale": 2.0e7}, "rig.toml[record.columns.pA]")
    50000.0
    """
    value = spec["accuracy"]
    if isinstance(value, str) and value.strip().endswith("%"):
        pct = _finite(value.strip()[:-1], f"{here}.accuracy", positive=True)
        if "full_scale" not in spec:
            raise ConfigError(f"{here}.accuracy {value!r} is a percentage of full scale: add "
                              "full_scale = <the sensor's range, in the column's unit>")
        return pct / 100.0 * _finite(spec["full_scale"], f"{here}.full_scale", positive=True)
    try:
        return _finite(value, f"{here}.accuracy", positive=True)
    except ConfigError:
        raise ConfigError(f"{here}.accuracy must be > 0: a number in the column's unit, or "
                          f"\"X %\" of full_scale; not {value!r}") from None


def parse_assignments(text: str | None, what: str) -> dict[str, str]:
    """``"a=1, b=2"`` -> ``{"a": "1", "b": "2"}`` (``what`` names the option in messages).

    Example
    -------
    >>> parse_assignments("theta=0.5, pA=1e3", "--scale")
    {'theta': '0.5', 'pA': '1e3'}
    """
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        if "=" not in item:
            raise ConfigError(f"{what}: cannot read {item.strip()!r}; write NAME=VALUE")
        key, value = (s.strip() for s in item.split("=", 1))
        if not key or not value:
            raise ConfigError(f"{what}: empty name or value in {item.strip()!r}")
        out[key] = value
    return out


def parse_record_settings(table: Mapping[str, Any] | None, where: str, *,
                          options: bool = False) -> RecordSettings:
    """Read a ``[record]`` table (from a declaration, ``unit.toml`` or a manifest row).

    Values may be TOML values or, as a manifest or the command line gives
    them, text: ``columns = "t=Time,theta=Angle"``, ``scale = "theta=3.8e-4"``,
    ``ignore = "F_Names,F_Values"``, ``sample_rate = "250"``.

    Parameters
    ----------
    table : mapping or None
        The table's entries (None or empty: no settings).
    where : str
        The file and table, named in every message.
    options : bool
        The entries are command-line options: messages name ``--sample-rate``,
        ``--scale`` ... instead of table keys.

    Returns
    -------
    RecordSettings

    Raises
    ------
    ConfigError
        An unknown key, a sample rate <= 0, a scale of 0 or a value that is
        not a finite number, a column named twice.

    Example
    -------
    >>> s = parse_record_settings({"sample_rate": 250, "columns": {
    ...     "theta": {"column": "Angle", "scale": 0.001}}}, "rig.toml[record]")
    >>> s.columns, s.scale, s.sample_rate
    ({'theta': 'Angle'}, {'theta': 0.001}, 250.0)
    """
    if not table:
        return RecordSettings(sources=())

    def at(key: str, name: str | None = None) -> str:
        if options:
            return f"--{key.replace('_', '-')}" + (f" {name}" if name else "")
        return f"{where}.{key}" + (f".{name}" if name else "")

    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table with {', '.join(RECORD_KEYS)}")
    unknown = [k for k in table if k not in RECORD_KEYS]
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r}; allowed: "
                          f"{', '.join(RECORD_KEYS)}")
    columns: dict[str, str] = {}
    scale: dict[str, float] = {}
    offset: dict[str, float] = {}
    accuracy: dict[str, float] = {}
    raw_cols = table.get("columns", {})
    if isinstance(raw_cols, str):
        raw_cols = parse_assignments(raw_cols, at("columns"))
    if not isinstance(raw_cols, Mapping):
        raise ConfigError(f"{where}.columns must be a table: model name = \"file column\" "
                          "or { column = ..., scale = ..., offset = ... }")
    for name, spec in raw_cols.items():
        here = at("columns", str(name))
        if isinstance(spec, str):
            if not spec.strip():
                raise ConfigError(f"{here}: empty file column name")
            columns[str(name)] = spec.strip()
            continue
        if not isinstance(spec, Mapping):
            raise ConfigError(f"{here} must be a file column name or a table "
                              "{ column = ..., scale = ..., offset = ... }")
        extra = [k for k in spec if k not in _COLUMN_KEYS]
        if extra:
            raise ConfigError(f"{here}: unknown key {extra[0]!r}; allowed: "
                              f"{', '.join(_COLUMN_KEYS)}")
        if "accuracy" in spec:
            accuracy[str(name)] = _accuracy(spec, here)
        elif "full_scale" in spec:
            raise ConfigError(f"{here}.full_scale is for an accuracy in % of full scale: "
                              "add accuracy = \"0.25 %\" (or give accuracy as a number)")
        if "column" in spec:
            if not isinstance(spec["column"], str) or not spec["column"].strip():
                raise ConfigError(f"{here}.column must be a file column name")
            columns[str(name)] = spec["column"].strip()
        if "scale" in spec:
            scale[str(name)] = _finite(spec["scale"], f"{here}.scale", nonzero=True)
        if "offset" in spec:
            offset[str(name)] = _finite(spec["offset"], f"{here}.offset")
    for key, target, nonzero in (("scale", scale, True), ("offset", offset, False)):
        extra_t = table.get(key, {})
        if isinstance(extra_t, str):
            extra_t = parse_assignments(extra_t, at(key))
        if not isinstance(extra_t, Mapping):
            raise ConfigError(f"{at(key)} must be a table NAME = number")
        for name, value in extra_t.items():
            target[str(name)] = _finite(value, at(key, str(name)), nonzero=nonzero)
    twice = sorted({c for c in columns.values() if list(columns.values()).count(c) > 1})
    if twice:
        raise ConfigError(f"{at('columns')}: file column {twice[0]!r} is mapped to more than "
                          "one model name")
    rate = table.get("sample_rate")
    fs = None if rate in (None, "") else _finite(rate, at("sample_rate"), positive=True)
    ignore = table.get("ignore", ())
    if isinstance(ignore, str):
        ignore = [c.strip() for c in ignore.split(",") if c.strip()]
    if not isinstance(ignore, (list, tuple)) or not all(isinstance(c, str) for c in ignore):
        raise ConfigError(f"{at('ignore')} must be a list of file column names")
    name_time = table.get("name_time")
    if name_time not in (None, ""):
        name_time = name_time_format(name_time, at("name_time"))
    return RecordSettings(columns, fs, scale, offset, tuple(ignore), (where,), accuracy,
                          name_time or None)


def apply_record_settings(df: pd.DataFrame, settings: RecordSettings | None,
                          source: str | None = None, *,
                          renamed: Mapping[str, str] | None = None) -> pd.DataFrame:
    """A record as read, turned into model columns in SI units.

    Parameters
    ----------
    df : pandas.DataFrame
        The record under the file's column names (``attrs`` are kept).
    settings : RecordSettings or None
        None or empty: ``df`` is returned as it is.
    source : str, optional
        Name of the record in messages (default ``df.attrs["source"]``).
    renamed : mapping, optional
        Model column -> file column already applied by the reader (named in
        an error about a scale given by the file's name).

    Returns
    -------
    pandas.DataFrame
        Ignored columns dropped, mapped columns renamed (a mapped column
        replaces a file column that already carries the model name), scaled
        columns as float64, and with a sample rate ``t`` in seconds from the
        first sample (``t`` made from the row number when the file has none);
        ``attrs["record_settings"]`` says what was done (it is not done twice).

    Raises
    ------
    DataError
        Naming the record and the column: a mapped or scaled column that is
        not in the file, a scaled column that is not numeric, a ``t`` that is
        not a sample counter although a sample rate is given.

    Example
    -------
    >>> s = RecordSettings(columns={"p": "PG"}, scale={"p": 2.0}, offset={"p": -1.0},
    ...                    sample_rate=4.0, ignore=("junk",))
    >>> import pandas as pd
    >>> out = apply_record_settings(pd.DataFrame({"PG": [1, 2], "junk": ["a", "b"]}), s)
    >>> out.columns.tolist(), out["p"].tolist(), out["t"].tolist()
    (['p', 't'], [1.0, 3.0], [0.0, 0.25])
    """
    if settings is None or settings.empty:
        return df
    import pandas as pd

    src = source or str(df.attrs.get("source", "record"))
    attrs = dict(df.attrs)
    dropped = [c for c in settings.ignore if c in df.columns]
    absent = [c for c in settings.ignore if c not in df.columns]
    if absent:
        warnings.warn(f"{src}: the record settings ignore column(s) {', '.join(map(repr, absent))}"
                      f", which the file does not have (its columns, as mapped: "
                      f"{', '.join(map(str, df.columns))})", DataWarning, stacklevel=2)
    out = df.drop(columns=dropped)
    missing = [f for f in settings.columns.values() if f not in out.columns]
    if missing:
        raise DataError(f"{src}: the record settings map column {missing[0]!r}, which the "
                        f"file does not have; its columns are {list(map(str, out.columns))} "
                        f"(settings from {', '.join(settings.sources) or 'the options'})")
    mapped = set(settings.columns.values())
    shadowed = [k for k in settings.columns if k in out.columns and k not in mapped]
    out = out.drop(columns=shadowed).rename(columns={v: k for k, v in settings.columns.items()})
    for name in sorted(set(settings.scale) | set(settings.offset)):
        if name not in out.columns:
            model_name = [k for k, v in {**(renamed or {}), **settings.columns}.items()
                          if v == name]
            hint = (f"; the columns map file column {name!r} to {model_name[0]!r}: scale "
                    f"and offset name the model's column ({model_name[0]}=...)"
                    if model_name else "")
            raise DataError(f"{src}: the record settings scale column {name!r}, which the "
                            f"record does not have; its columns are "
                            f"{list(map(str, out.columns))}{hint}")
        values = pd.to_numeric(out[name], errors="coerce")
        # a missing cell stays missing (the record's checks name it); only text
        # that is no number is refused here, quoted as the file has it
        text = values.isna().to_numpy() & ~out[name].isna().to_numpy()
        if text.any():
            row = int(np.flatnonzero(text)[0])
            file_col = settings.columns.get(name, name)
            named = f"{name!r}" + (f" (file column {file_col!r})" if file_col != name else "")
            raise DataError(f"{src}: column {named} is not numeric (row {row}: "
                            f"{str(out[name].iloc[row])!r}); it cannot be scaled")
        out[name] = (values.to_numpy(dtype=np.float64) * settings.scale.get(name, 1.0)
                     + settings.offset.get(name, 0.0))
    if settings.sample_rate is not None:
        out["t"] = _seconds(out, settings.sample_rate, src)
    if settings.name_time and not attrs.get("start_time"):
        # a name without the time (a simulated test, a renamed file) leaves the
        # start unknown: a session condition then says so
        when = time_in_name(Path(src).name, settings.name_time)
        if when is not None:
            attrs["start_time"] = when.isoformat()
    out.attrs.update(attrs)
    out.attrs["record_settings"] = settings.describe(len(dropped))
    out.attrs["record_ignored"] = dropped
    return out


def rig_layout(df: pd.DataFrame, settings: RecordSettings | None) -> pd.DataFrame:
    """A record in model columns and SI units, written back as the rig writes it.

    The inverse of :func:`apply_record_settings` (ignored columns are not made
    up): each column scaled back (``raw = (value - offset) / scale``), renamed
    to the file's name, and with a sample rate ``t`` turned into a sample
    counter from 1. A simulated record so written reads back through the same
    settings as a file from the rig.

    Example
    -------
    >>> s = RecordSettings(columns={"t": "Time", "p": "PG"}, scale={"p": 2.0},
    ...                    offset={"p": -1.0}, sample_rate=4.0)
    >>> import pandas as pd
    >>> raw = rig_layout(pd.DataFrame({"t": [0.0, 0.25], "p": [1.0, 3.0]}), s)
    >>> raw.columns.tolist(), raw["PG"].tolist(), raw["Time"].tolist()
    (['Time', 'PG'], [1.0, 2.0], [1, 2])
    >>> apply_record_settings(raw, s)["p"].tolist()
    [1.0, 3.0]
    """
    if settings is None or settings.empty:
        return df
    out = df.copy()
    for name in sorted(set(settings.scale) | set(settings.offset)):
        if name in out.columns:
            out[name] = ((out[name].to_numpy(dtype=np.float64) - settings.offset.get(name, 0.0))
                         / settings.scale.get(name, 1.0))
    if settings.sample_rate is not None and "t" in out.columns:
        out["t"] = np.rint(out["t"].to_numpy(dtype=np.float64) * settings.sample_rate
                           ).astype(np.int64) + 1
    out = out.rename(columns={k: v for k, v in settings.columns.items() if k in out.columns})
    out.attrs = dict(df.attrs)
    return out


def _seconds(df: pd.DataFrame, fs: float, src: str) -> np.ndarray[Any, np.dtype[np.float64]]:
    """``t`` in seconds from a sample counter (or the row number) at ``fs`` [Hz];
    a ``t`` already stepping by ``1/fs`` is taken as seconds."""
    import pandas as pd

    n = len(df)
    if "t" not in df.columns:
        return np.arange(n, dtype=np.float64) / fs
    counter = pd.to_numeric(df["t"], errors="coerce").to_numpy(dtype=np.float64)
    if n and not np.all(np.isfinite(counter)):
        row = int(np.flatnonzero(~np.isfinite(counter))[0])
        raise DataError(f"{src}: column 't' is not a sample counter (row {row}: "
                        f"{df['t'].iloc[row]!r})")
    steps = np.diff(counter)
    if steps.size and bool(np.all(np.abs(steps * fs - 1.0) <= 1e-6)):
        # already seconds at the stated rate (t = 0, 4, 8 at 0.25 Hz): read as a
        # counter, a record 4 s apart became 16 s apart, and every rate 4x off
        return np.asarray(counter - counter[0], dtype=np.float64)
    bad = np.flatnonzero((np.abs(steps - np.round(steps)) > 1e-6) | (steps <= 0))
    if bad.size:
        k = int(bad[0])
        raise DataError(f"{src}: column 't' does not count samples (step {steps[k]:.6g} at row "
                        f"{k + 1}) although a sample rate ({fs:g} Hz) is given; give the "
                        "sample rate only when t is a sample index, or map t to a time in "
                        "seconds")
    if steps.size and float(np.median(steps)) != 1.0:
        raise DataError(f"{src}: column 't' steps by {float(np.median(steps)):g}: a sample "
                        f"counter steps by 1, and seconds at the stated {fs:g} Hz by "
                        f"{1.0 / fs:g}; which is it? give t in seconds and no sample rate, "
                        "or a counter")
    return (counter - counter[0]) / fs if n else counter


def settings_from_options(columns: Mapping[str, str] | None = None,
                          sample_rate: float | None = None,
                          scale: str | Mapping[str, Any] | None = None,
                          offset: str | Mapping[str, Any] | None = None,
                          ignore: str | Sequence[str] | None = None,
                          where: str = "command line") -> RecordSettings:
    """Settings given as options (the command line's ``--columns``,
    ``--sample-rate``, ``--scale``, ``--offset``, ``--ignore``).

    Example
    -------
    >>> settings_from_options(sample_rate=250.0, scale="theta=0.5").scale
    {'theta': 0.5}
    """
    table: dict[str, Any] = {}
    if columns:
        table["columns"] = dict(columns)
    if sample_rate is not None:
        table["sample_rate"] = sample_rate
    if scale:
        table["scale"] = scale
    if offset:
        table["offset"] = offset
    if ignore:
        table["ignore"] = ignore if isinstance(ignore, str) else list(ignore)
    return parse_record_settings(table, where, options=True) if table else RecordSettings()
