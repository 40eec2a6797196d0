"""Checks of a record against a declared plant model, before any residual.

A record that cannot be right is refused with one line naming the file and the
column (:class:`~condmon.errors.DataError`); one that is usable but suspicious
gets a :class:`~condmon.errors.DataWarning`. The limits are data
(``[record]`` of ``condmon/data/isolation.toml``):

- every value finite and numeric; ``t`` increasing and uniformly sampled;
- a sensor or input value further outside its declared range than
  ``refuse_outside_spans`` times the range's span: refused (a unit error, a
  corrupt file); more than 1 % of a column's samples outside the range, by
  less: a warning (a real sensor saturates there);
- a sensor column whose largest magnitude is below ``dead_fraction`` of its
  range span and whose whole excursion is below its declared noise: refused (a
  dead sensor, or a unit 1e3–1e5 times too large, e.g. bar for Pa);
- a sample interval ``time_base_factor`` times shorter or longer than the
  test's: refused (time in the wrong unit, e.g. milliseconds as seconds); a
  record shorter than ``short_fraction`` of the test: a warning.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.io.records import check_time_base, row_text
from condmon.errors import ConfigError, DataError, DataWarning, MissingColumnsError
from condmon.io.columns import Columns
from condmon.io.config import load_default
from condmon.models.declared import PlantModel

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["RecordSettings", "validate_plant_record", "check_stream_chunk"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RecordSettings:
    """Limits of the record checks (defaults: ``[record]`` of ``isolation.toml``).

    Attributes
    ----------
    refuse_outside_spans : float
        A value further outside its declared range than this many range spans
        is refused. [-]
    dead_fraction : float
        A sensor column below this fraction of its range span, with an
        excursion below its noise, is refused. [-]
    time_base_factor : float
        A sample interval this many times shorter or longer than the test's is
        refused. [-]
    short_fraction : float
        A record shorter than this fraction of the test's duration is warned of. [-]
    unit_share : float
        A sensor column more than this share of whose samples lie beyond
        ``unit_factor`` x its range's largest magnitude, or (for a range that
        starts at 0) below it by more than 3 noise deviations, is refused as a
        likely unit or sign error. [-]
    unit_factor : float
        See ``unit_share``. [-]
    """

    refuse_outside_spans: float = 10.0
    dead_fraction: float = 1e-3
    time_base_factor: float = 300.0
    short_fraction: float = 0.1
    unit_share: float = 0.5
    unit_factor: float = 3.0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None = None) -> RecordSettings:
        """The ``[record]`` table of a settings document (default: the shipped one)."""
        r = (cfg or load_default("isolation.toml"))["record"]
        out = cls(float(r["refuse_outside_spans"]), float(r["dead_fraction"]),
                  float(r["time_base_factor"]), float(r["short_fraction"]),
                  float(r.get("unit_share", 0.5)), float(r.get("unit_factor", 3.0)))
        if not (out.refuse_outside_spans > 0 and 0 <= out.dead_fraction < 1
                and out.time_base_factor > 1 and 0 <= out.short_fraction <= 1
                and 0 < out.unit_share <= 1 and out.unit_factor > 1):
            raise ConfigError(f"[record]: refuse_outside_spans > 0, 0 <= dead_fraction < 1, "
                              f"time_base_factor > 1, 0 <= short_fraction <= 1, 0 < unit_share <= 1 and "
                              f"unit_factor > 1 (got {out})")
        return out


def validate_plant_record(model: PlantModel, record: pd.DataFrame | Columns,
                          source: str = "record", settings: RecordSettings | None = None
                          ) -> pd.DataFrame | Columns:
    """Check a record against a model (see the module's list); the record, reindexed
    (a DataFrame, or :class:`~condmon.io.columns.Columns` when given them).

    Raises
    ------
    DataError
        Naming ``source`` and the column.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> m = load_plant_model("hst")
    >>> rec = simulate_plant(m, seed=1)
    >>> rec["Ps"] = rec["Ps"] / 1e5          # bar where the declaration says Pa
    >>> validate_plant_record(m, rec, "rig.csv")
    Traceback (most recent call last):
    ...
    condmon.errors.DataError: rig.csv: column 'Ps' stays within [0.0864, 66.8] Pa, less than its noise (25000 Pa) and below 0.001 of its range [0, 1e+07] Pa: a dead sensor, or a value in a larger unit (bar for Pa?)
    """
    cfg = settings or RecordSettings.from_config()
    missing = [c for c in ("t", *model.sensor_names) if c not in record.columns]
    if missing:
        raise MissingColumnsError(f"{source}: missing column {missing[0]!r}; model "
                                  f"{model.name!r} needs t, {', '.join(model.sensor_names)}",
                                  tuple(missing), tuple(map(str, record.columns)))
    inputs = [u for u in model.inputs if u.name in record.columns]
    values: dict[str, FloatArray] = {}
    for c in ["t", *model.sensor_names, *(u.name for u in inputs)]:
        v = record[c] if isinstance(record, Columns) else _numbers(record, c)
        if not np.all(np.isfinite(v)):
            k = int(np.flatnonzero(~np.isfinite(v))[0])
            header = int(record.attrs.get("header_line", 1))
            raise DataError(f"{source}: column {c!r} has a missing or non-numeric value at "
                            f"{row_text(k, source, header)}")
        values[c] = v
    t = values["t"]
    if len(t) < 10:
        raise DataError(f"{source}: {len(t)} samples; at least 10 are needed")
    check_time_base(t, source)  # one tolerance for every command, jitter in the message
    _check_time_base(model, t, source, cfg)
    for u in inputs:
        _far_outside(values[u.name], u.name, "input", u.range, u.unit, source, cfg)
        share = float(np.mean((values[u.name] < u.range[0]) | (values[u.name] > u.range[1])))
        if share > 0.01:
            warnings.warn(f"{source}: {share:.0%} of column {u.name!r} lies outside the input's "
                          f"range [{u.range[0]:g}, {u.range[1]:g}] {u.unit}", DataWarning,
                          stacklevel=3)
    for s in model.sensors:
        y = values[s.name]
        _far_outside(y, s.name, "sensor", s.range, s.unit, source, cfg)
        _dead(y, s.name, s.range, s.noise, s.unit, source, cfg)
        _unit_or_sign(y, s.name, s.range, s.noise, s.unit, source, cfg)
        lo, hi = s.range
        share = float(np.mean((y < lo) | (y > hi)))
        if share > 0.01:
            warnings.warn(f"{source}: {share:.0%} of column {s.name!r} lies outside the "
                          f"sensor's range [{lo:g}, {hi:g}] {s.unit}; a real sensor would "
                          "saturate there", DataWarning, stacklevel=3)
        elif np.ptp(y) == 0:
            warnings.warn(f"{source}: column {s.name!r} is constant ({y[0]:g} {s.unit}): a stuck "
                          "sensor or a noise-free record", DataWarning, stacklevel=3)
    if isinstance(record, Columns):
        return Columns({**{c: record[c] for c in record.columns}, **values}, record.attrs)
    out = record.reset_index(drop=True).copy()
    for c, v in values.items():
        out[c] = v
    return out


def _numbers(record: pd.DataFrame, column: str) -> FloatArray:
    """A column as float64, what is not a number as NaN."""
    import pandas as pd

    return np.asarray(pd.to_numeric(record[column], errors="coerce").to_numpy(dtype=np.float64),
                      dtype=np.float64)


def _check_time_base(model: PlantModel, t: FloatArray, source: str, cfg: RecordSettings) -> None:
    _check_interval(model, float(np.mean(np.diff(t))), source, cfg)
    duration = float(t[-1] - t[0])
    if duration < cfg.short_fraction * model.test.duration:
        warnings.warn(f"{source}: the record lasts {duration:.3g} s, far less than the test's "
                      f"{model.test.duration:g} s", DataWarning, stacklevel=4)


def _check_interval(model: PlantModel, dt: float, source: str, cfg: RecordSettings) -> None:
    """A sample interval [s] within ``time_base_factor`` of the test's."""
    test_dt = 1.0 / model.test.sample_rate
    ratio = dt / test_dt
    if ratio >= cfg.time_base_factor or ratio <= 1.0 / cfg.time_base_factor:
        how = f"{ratio:.3g} times longer" if ratio > 1 else f"{1 / ratio:.3g} times shorter"
        raise DataError(f"{source}: the sample interval {dt:.3g} s is {how} than the test's "
                        f"{test_dt:.3g} s: column 't' must be in seconds (milliseconds given "
                        "as seconds, or the reverse?)")


def check_stream_chunk(model: PlantModel, cols: Mapping[str, FloatArray], source: str,
                       settings: RecordSettings | None = None) -> None:
    """The checks of :func:`validate_plant_record` that hold for a piece of a
    stream, with the same messages: uniform sampling, the sample interval
    against the test's, sensors and inputs far outside their declared ranges.
    (A stream at rest is not a dead sensor, and a chunk is always short: those
    checks need a whole record.)

    Raises
    ------
    DataError
        Naming ``source`` (the unit and topic) and the column.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> check_stream_chunk(load_plant_model("hst"), {"t": np.array([0.0, 1000.0]),
    ...                    "Ps": np.zeros(2), "omega_m": np.zeros(2)}, "unit 'U'")
    Traceback (most recent call last):
    ...
    condmon.errors.DataError: unit 'U': the sample interval 1e+03 s is 1e+05 times longer than the test's 0.01 s: column 't' must be in seconds (milliseconds given as seconds, or the reverse?)
    """
    cfg = settings or RecordSettings()
    t = np.asarray(cols["t"], dtype=np.float64)
    if len(t) > 1:
        _check_interval(model, check_time_base(t, source), source, cfg)
    for u in model.inputs:
        if u.name in cols and u.range is not None:
            _far_outside(np.asarray(cols[u.name], dtype=np.float64), u.name, "input", u.range,
                         u.unit, source, cfg)
    for sn in model.sensors:
        if sn.name in cols:
            _far_outside(np.asarray(cols[sn.name], dtype=np.float64), sn.name, "sensor",
                         sn.range, sn.unit, source, cfg)


def _unit_or_sign(y: FloatArray, name: str, rng: tuple[float, float], noise: float, unit: str,
                  source: str, cfg: RecordSettings) -> None:
    """Refuse a sensor column that mostly reads far beyond its range (a unit
    error: rpm for rad/s) or below a range that starts at 0 (a sign error)."""
    lo, hi = rng
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return
    big = cfg.unit_factor * max(abs(lo), abs(hi))
    far = float(np.mean(np.abs(y) > big))
    if far > cfg.unit_share:
        raise DataError(f"{source}: {far:.0%} of column {name!r} lies beyond {cfg.unit_factor:g} x "
                        f"its sensor's range [{lo:g}, {hi:g}] {unit}: likely a unit error "
                        "(rpm for rad/s? bar for Pa?)")
    if lo == 0.0:
        below = float(np.mean(y < -3.0 * noise))
        if below > cfg.unit_share:
            raise DataError(f"{source}: {below:.0%} of column {name!r} is negative although its "
                            f"sensor's range is [{lo:g}, {hi:g}] {unit}: likely a sign error")


def _far_outside(y: FloatArray, name: str, what: str, rng: tuple[float, float], unit: str,
                 source: str, cfg: RecordSettings) -> None:
    lo, hi = rng
    span = hi - lo
    if not math.isfinite(span):
        return
    worst = float(np.max(np.maximum(lo - y, y - hi)))
    if worst > cfg.refuse_outside_spans * span:
        k = int(np.argmax(np.maximum(lo - y, y - hi)))
        raise DataError(f"{source}: column {name!r} reaches {y[k]:.4g} {unit} at row {k}, more "
                        f"than {cfg.refuse_outside_spans:g} spans outside the {what}'s declared "
                        f"range [{lo:g}, {hi:g}] {unit}: wrong unit, or not this {what}?")


def _dead(y: FloatArray, name: str, rng: tuple[float, float], noise: float, unit: str,
          source: str, cfg: RecordSettings) -> None:
    span = rng[1] - rng[0]
    if not math.isfinite(span):
        return
    if float(np.max(np.abs(y))) < cfg.dead_fraction * span and float(np.ptp(y)) < noise:
        raise DataError(f"{source}: column {name!r} stays within [{y.min():.3g}, {y.max():.3g}] "
                        f"{unit}, less than its noise ({noise:g} {unit}) and below "
                        f"{cfg.dead_fraction:g} of its range [{rng[0]:g}, {rng[1]:g}] {unit}: a "
                        "dead sensor, or a value in a larger unit (bar for Pa?)")
