"""Property-based tests: whatever record, rule file or declaration a user brings,
condmon answers with a result or one clear error — never a traceback.

About 1,000 generated cases in the default run (derandomised: the same cases
every run, so the suite stays deterministic).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from condmon.cli.main import main
from condmon.errors import CondmonError, CondmonWarning
from condmon.identify import estimate
from condmon.models.registry import get_model
from condmon.simulate import simulate_actuator

FAST = settings(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

_BASE = simulate_actuator(seed=123)
_SHORT = _BASE.iloc[:1500].reset_index(drop=True)
COLUMNS = ("V", "I", "omega", "yd", "ud")
WEIRD = [0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 1e300, -1e300, 1e15, 1e16,
         float("nan"), float("inf"), -float("inf")]


@st.composite
def columns_from_real(draw: st.DrawFn) -> pd.DataFrame:
    """A real simulated record, then mangled the ways users mangle records."""
    df = (_BASE if draw(st.booleans()) else _SHORT).copy()
    for _ in range(draw(st.integers(0, 3))):
        col = draw(st.sampled_from(("t", *COLUMNS)))
        op = draw(st.sampled_from(("scale", "negate", "spike", "constant", "drop",
                                   "truncate", "copy", "noise", "nan", "round")))
        if col not in df.columns or (op == "spike" and not len(df)):
            continue
        if op == "scale":
            df[col] = df[col] * draw(st.sampled_from([1e-3, 1e3, 60 / (2 * math.pi), 1e6, -1.0]))
        elif op == "negate":
            df[col] = -df[col]
        elif op == "spike":
            row = draw(st.integers(0, len(df) - 1))
            df.loc[row, col] = draw(st.sampled_from(WEIRD))
        elif op == "constant":
            df[col] = draw(st.sampled_from([0.0, 1.0, 1e-12]))
        elif op == "drop" and col in df.columns and col != "t":
            df = df.drop(columns=[col])
        elif op == "truncate":
            df = df.iloc[: draw(st.integers(0, len(df)))].reset_index(drop=True)
        elif op == "copy":
            other = draw(st.sampled_from(COLUMNS))
            if other in df.columns:
                df[col] = df[other]
        elif op == "noise" and len(df):
            scale = draw(st.sampled_from([1e-6, 1.0, 100.0]))
            df[col] = df[col] + scale * np.random.default_rng(draw(st.integers(0, 99))
                                                               ).standard_normal(len(df))
        elif op == "nan" and len(df):
            df.loc[draw(st.integers(0, len(df) - 1)), col] = float("nan")
        elif op == "round":
            df[col] = df[col].round(draw(st.integers(0, 3)))
    return df


@st.composite
def synthetic(draw: st.DrawFn) -> pd.DataFrame:
    """Records built from nothing: any length, sample interval and values."""
    n = draw(st.integers(0, 2500))
    dt = draw(st.sampled_from([1e-3, 5e-4, 1e-4, 2e-3, 1.0, 1e-7, 0.0]))
    t = np.arange(n) * dt
    if draw(st.booleans()) and n > 3:
        t[draw(st.integers(1, n - 1))] -= dt * draw(st.sampled_from([0.5, 2.0, 1e-6]))
    data: dict[str, Any] = {"t": t}
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    for col in ("V", "I", "omega"):
        kind = draw(st.sampled_from(("noise", "sine", "const", "weird", "text", "missing")))
        if kind == "noise":
            data[col] = draw(st.sampled_from([1e-9, 1.0, 1e6])) * rng.standard_normal(n)
        elif kind == "sine":
            data[col] = np.sin(2 * np.pi * draw(st.sampled_from([1.0, 50.0, 499.0])) * t)
        elif kind == "const":
            data[col] = np.full(n, draw(st.sampled_from(WEIRD)))
        elif kind == "weird":
            data[col] = np.array(draw(st.lists(st.sampled_from(WEIRD), min_size=n,
                                                max_size=n)), dtype=float) if n < 200 else \
                rng.choice(np.array(WEIRD), n)
        elif kind == "text":
            data[col] = ["x"] * n
    return pd.DataFrame(data)


def _check_result_or_refusal(df: pd.DataFrame, **kw: Any) -> None:
    try:
        with warnings.catch_warnings():
            # condmon's own warnings (saturated input, ...) are answers too;
            # any other warning (numpy's RuntimeWarning) stays an error.
            warnings.simplefilter("ignore", CondmonWarning)
            res = estimate(df, source="generated", **kw)
    except CondmonError as err:
        msg = str(err)
        assert msg and "\n" not in msg
        return
    doc = res.to_dict()
    json.dumps(doc, allow_nan=False)  # never NaN/inf in JSON
    if res.accepted:
        plaus = get_model("dc-motor").spec.plausibility
        assert plaus.check_values(res.parameters, res.units, res.std_errors) is None
        assert all(math.isfinite(v) for v in res.std_errors.values())
    else:
        assert res.reason


@settings(FAST, max_examples=380)
@given(columns_from_real(), st.sampled_from(["sriv", "oe", "iv", "arx"]),
       st.sampled_from(["auto", None]))
def test_estimate_on_mangled_real_records(df: pd.DataFrame, method: str,
                                          excitation: str | None) -> None:
    _check_result_or_refusal(df, method=method, excitation=excitation)


@settings(FAST, max_examples=300)
@given(synthetic())
def test_estimate_on_synthetic_records(df: pd.DataFrame) -> None:
    _check_result_or_refusal(df)


def _cli(args: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    return rc, out.getvalue(), err.getvalue()


@settings(FAST, max_examples=60)
@given(columns_from_real(), st.sampled_from([[], ["--json"], ["--gamma", "0"],
                                             ["--gamma", "-1"], ["--excitation", "none"],
                                             ["--fit-threshold", "120"],
                                             ["--columns", "V=nope"]]))
def test_cli_estimate_never_shows_a_traceback(df: pd.DataFrame, extra: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rec.csv"
        df.to_csv(path, index=False)
        rc, out, err = _cli(["estimate", str(path), *extra])
    assert rc in (0, 2), (rc, err)
    assert "Traceback" not in err
    if rc == 2:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), err
    elif "--json" in extra:
        json.loads(out)


# --- rule files and monitor settings ------------------------------------------

_TOKENS = ["high(D)", "low(R)", "high(L)", "high(Q)", "and", "or", "not", "(", ")",
           "high(", "low()", "xor", "1", "", "high(D) and", "not not high(R)"]


def _toml_str(s: str) -> str:
    return json.dumps(s)  # a JSON string is a valid TOML basic string


@st.composite
def rule_files(draw: st.DrawFn) -> str:
    lines = []
    for _ in range(draw(st.integers(0, 4))):
        cond = " ".join(draw(st.lists(st.sampled_from(_TOKENS), min_size=0, max_size=6)))
        lines.append("[[fault]]")
        if draw(st.booleans()):
            lines.append(f"name = {_toml_str(draw(st.text(max_size=12)))}")
        lines.append(f"if = {_toml_str(cond)}")
        sev = draw(st.sampled_from(["major", "minor", "severe", "", "1"]))
        lines.append(f"severity = {_toml_str(sev)}" if sev != "1" else "severity = 1")
        if draw(st.booleans()):
            lines.append(f"advice = {_toml_str(draw(st.text(max_size=10)))}")
    if draw(st.booleans()):
        lines += ["[status]", f"go = {draw(st.sampled_from(['[0, 0, 0.5]', '[1, 0]', '3', '[0.5, 0.2, 0.1]']))}"]
    if draw(st.booleans()):
        lines.append(draw(st.sampled_from(["[[preprocess]]\nname = 'x'\nif_dominant = 'high(D)'\nclear = ['high(J)']",
                                           "[[preprocess]]\nclear = 5", "garbage = [", "= 1"])))
    return "\n".join(lines) + "\n"


@settings(FAST, max_examples=150)
@given(rule_files())
def test_rule_files_load_or_refuse_with_one_line(text: str) -> None:
    from condmon.diagnose.rules import load_rules

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rules.toml"
        path.write_text(text, encoding="utf-8")
        try:
            load_rules(path)
        except CondmonError as err:
            assert str(err) and "Traceback" not in str(err)


@st.composite
def monitor_files(draw: st.DrawFn) -> str:
    vals = st.sampled_from(["10", "-5", "0", "1e300", "'x'", "[1, 2]", "nan", "inf"])
    keys = ["k", "r1", "r2", "margin", "unknown"]
    lines = [f"{k} = {draw(vals)}" for k in keys if draw(st.booleans())]
    if draw(st.booleans()):
        lines.insert(0, draw(st.sampled_from(["[D]", "[breakpoints]", "[R]"])))
    return "\n".join(lines) + "\n"


@settings(FAST, max_examples=60)
@given(monitor_files())
def test_monitor_files_load_or_refuse(text: str) -> None:
    from condmon.monitor.fuzzy import load_monitor_config

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "monitor.toml"
        path.write_text(text, encoding="utf-8")
        try:
            load_monitor_config(path)
        except CondmonError as err:
            assert str(err)


# --- plant declarations -----------------------------------------------------------

_HST = (Path(__file__).parents[1] / "src" / "condmon" / "data" / "hst.toml").read_text()
_EXPRS = ["Kp*(Dp*omega_p - Q)", "1/0", "sqrt(-1)", "Ps**", "__import__('os')", "sign(Ps)",
          "unknown_name*2", "Ps; Pm", "log(0)", "exp(1e6)", "abs(Ps - Pm)", "", "max(Ps, Pm)",
          "lambda: 1", "Ps if Pm else 0", "[Ps]", "Ps.real", "1e400"]


@st.composite
def declarations(draw: st.DrawFn) -> str:
    text = _HST
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["equation", "value", "drop", "range", "noise", "name"]))
        if op == "equation":
            target = draw(st.sampled_from(['"Kp*(Dp*omega_p - Q - Ps/Rlkgp)"',
                                           '"(Dm*Pm - Rv*omega_m - Tld)/J"',
                                           '"Cd*Ao*sign(Ps - Pm)*sqrt(2*abs(Ps - Pm)/rho)"']))
            text = text.replace(target, _toml_str(draw(st.sampled_from(_EXPRS))))
        elif op == "value":
            text = text.replace("value = 6.18", "value = " + draw(st.sampled_from(
                ["0.0", "-1.0", "1e308", "'heavy'", "nan", "inf"])))
        elif op == "drop":
            section = draw(st.sampled_from(["[inputs]", "[states]", "[sensors]", "[test]",
                                            "[variables]", "[parameters]"]))
            text = text.replace(section, "[dropped" + str(draw(st.integers(0, 9))) + "]")
        elif op == "range":
            text = text.replace("range = [0.0, 1.0e7]", "range = " + draw(st.sampled_from(
                ["[1.0e7, 0.0]", "[0.0]", "'wide'", "[0.0, nan]"])))
        elif op == "noise":
            text = text.replace("noise = 2.5e4", "noise = " + draw(st.sampled_from(
                ["0.0", "-1.0", "'low'", "inf"])))
        elif op == "name":
            text = text.replace('measures = "Ps"', "measures = " + _toml_str(
                draw(st.sampled_from(["Q", "nothing", "", "Pm"]))))
    return text


@settings(FAST, max_examples=60)
@given(declarations())
def test_declarations_load_or_refuse_with_one_line(text: str) -> None:
    from condmon.models.registry import load_plant_model

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plant.toml"
        path.write_text(text, encoding="utf-8")
        try:
            load_plant_model(path)
        except CondmonError as err:
            assert str(err)
