"""Property-based tests of routine records: whatever [record] table, regime
condition or raw stand file a user brings, condmon answers with a result or
one clear error — never a traceback, never an estimate that breaks a bound.

Derandomised (the same cases every run).
"""

from __future__ import annotations

import math
import string
import warnings
from typing import Any

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _strokes import DECLARATION, stroke
from condmon.errors import CondmonError, ConfigError, DataError, DataWarning
from condmon.identify import estimate
from condmon.io.rig import apply_record_settings, parse_record_settings
from condmon.models.regimes import parse_condition
from condmon.models.registry import get_model

FAST = settings(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6),
                    st.sampled_from([0, -1, "250", "abc", "", "inf", "1e400", True, None]))
NAMES = st.sampled_from(["t", "theta", "pA", "pB", "Time", "Angle", "PG_1", "x", "", " "])


@st.composite
def record_tables(draw: st.DrawFn) -> dict[str, Any]:
    table: dict[str, Any] = {}
    if draw(st.booleans()):
        table["sample_rate"] = draw(NUMBERS)
    if draw(st.booleans()):
        cols: dict[str, Any] = {}
        for _ in range(draw(st.integers(0, 4))):
            spec = draw(st.one_of(NAMES, st.fixed_dictionaries(
                {"column": NAMES}, optional={"scale": NUMBERS, "offset": NUMBERS,
                                             "junk": NUMBERS})))
            cols[draw(NAMES)] = spec
        table["columns"] = draw(st.sampled_from([cols, "t=Time,theta=Angle", "bad", 3]))
    for key in ("scale", "offset"):
        if draw(st.booleans()):
            table[key] = draw(st.one_of(st.dictionaries(NAMES, NUMBERS, max_size=3),
                                        st.sampled_from(["theta=2", "theta", 5])))
    if draw(st.booleans()):
        table["ignore"] = draw(st.one_of(st.lists(NAMES, max_size=3), st.sampled_from(["a,b", 1])))
    if draw(st.booleans()):
        table[draw(st.sampled_from(["rate", "colums"]))] = 1
    return table


@settings(FAST, max_examples=300)
@given(record_tables())
def test_record_tables_are_read_or_refused_by_name(table: dict[str, Any]) -> None:
    try:
        s = parse_record_settings(table, "rig.toml[record]")
    except ConfigError as err:
        assert str(err).startswith(("rig.toml[record]", "--")) and "\n" not in str(err)
        return
    assert s.sample_rate is None or (math.isfinite(s.sample_rate) and s.sample_rate > 0)
    assert all(math.isfinite(v) and v != 0 for v in s.scale.values())
    raw = stroke(1.0, n=300)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            out = apply_record_settings(raw, s, "r.txt")
        except DataError as err:
            assert str(err).startswith("r.txt") and "\n" not in str(err)
            return
    assert all(issubclass(w.category, DataWarning) for w in caught)
    assert len(out) == len(raw)


ATOMS = st.sampled_from(["omega", "theta", "pA", "load", "T", "1", "0.1", "-2", "'ball'",
                         "1e308", "x", "__class__", "abs(omega)", "sign(pA - pB)"])
OPS = st.sampled_from([" > ", " < ", " >= ", " == ", " != ", " and ", " or ", " + ", " * ",
                       " / ", " ** ", " ** 2 > ", ".", "(", ")", " not ", ","])


@st.composite
def conditions(draw: st.DrawFn) -> str:
    parts = [draw(ATOMS)]
    for _ in range(draw(st.integers(0, 6))):
        parts += [draw(OPS), draw(ATOMS)]
    if draw(st.booleans()):
        return draw(st.text(alphabet=string.printable, max_size=40))
    return "".join(parts)


@settings(FAST, max_examples=400)
@given(conditions())
def test_conditions_parse_and_evaluate_or_refuse(text: str) -> None:
    try:
        cond = parse_condition(text, "m.toml[regimes.a]")
    except ConfigError as err:
        assert "m.toml[regimes.a]" in str(err) and "\n" not in str(err)
        return
    rng = np.random.default_rng(0)
    signals = {k: rng.standard_normal(20) for k in ("omega", "theta", "pA", "pB", "T")}
    try:
        hit = cond.evaluate(signals, {"load": "ball"}, 20, "r.txt")
    except DataError as err:
        assert str(err).startswith("r.txt") and "\n" not in str(err)
        return
    assert hit.shape == (20,) and hit.dtype == np.bool_


@st.composite
def stand_records(draw: st.DrawFn) -> pd.DataFrame:
    speed = draw(st.sampled_from([1.0, -1.0, 0.3, -2.0, 0.05, 0.0]))
    df = stroke(speed, seed=draw(st.integers(0, 5)), hold_only=draw(st.booleans()),
                stroke_s=draw(st.sampled_from([1.6, 0.5, 0.1, 11.0])),
                friction={"Tc": draw(st.sampled_from([40.0, 0.0, -5.0, 1e6]))})
    for _ in range(draw(st.integers(0, 2))):
        col = draw(st.sampled_from(["Angle", "PG_1", "PG_2", "Time"]))
        op = draw(st.sampled_from(["negate", "constant", "spike", "drop", "truncate"]))
        if col not in df.columns or not len(df):
            continue
        if op == "negate":
            df[col] = -df[col]
        elif op == "constant":
            df[col] = 7
        elif op == "spike":
            df.loc[draw(st.integers(0, len(df) - 1)), col] = 16383 * 10**9
        elif op == "drop":
            df = df.drop(columns=[col])
        else:
            df = df.iloc[: draw(st.integers(0, 600))].reset_index(drop=True)
    return df


MODEL = get_model(str(DECLARATION))


@settings(FAST, max_examples=120)
@given(stand_records())
def test_raw_stand_records_estimate_or_refuse(df: pd.DataFrame) -> None:
    try:
        res = estimate(df, MODEL, source="r.txt")
    except CondmonError as err:
        assert "r.txt" in str(err) and "\n" not in str(err)
        return
    if res.accepted:
        assert res.parameters["Tc"] >= -3 * res.std_errors["Tc"]
        assert res.identified and res.regime in ("forward", "reverse")
    else:
        assert res.reason and "\n" not in res.reason
        assert all(math.isfinite(v) for v, _ in res.stored_values().values())
