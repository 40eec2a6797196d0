"""Prognostics on simulated fleets with known truth (the actuator, nonlinear effects on).

    python benchmarks/bench_prognostics.py [--units 30]
    pip install exponential-degradation-model   # the peer (optional; skipped with a note)

1. Run to failure. Each unit wears one parameter (friction D with the Coulomb
   friction alike, or the winding resistance R), linearly (``1 + r·k``) or
   exponentially (``1 + 0.1·(exp(r·k) − 1)``), at a rate drawn so that the true
   parameter reaches its no-go change (r2: R +40 %, D +600 %) after 12-30 tests.
   A 3-5 test healthy baseline, then checks (simulate, ``check_test`` into an
   in-memory store) until the *estimated* change crosses r2: that test is the
   unit's end of life. The forecasts are made on the stored series (read as
   ``forecast_unit`` reads it; checked against it on the full series) cut at
   λ = 0.5 and 0.75 of each life, and scored by the α-λ accuracy (α = 0.2: the
   share of units whose median RUL is within ±20 % of the true RUL), the
   coverage of the 90 % interval, and the median relative error. Again with the
   fleet prior (leave-one-out: from the other units that wore the same
   parameter, their full series; the model the unit's own evidence chooses),
   and with the peer ``exponential-degradation-model`` (Gebraeel 2006, as
   MATLAB's exponentialDegradationModel) fed the same series as
   ``ln(S − φ)`` of the signal ``S = 1 + change/100`` (its default φ = −1 and
   vague priors), the threshold ``1 + r2/100``.

Prints a table per section and writes results/bench_prognostics.json.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import dataclasses
import math
import sys
import time
import warnings
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from _common import table, write_json
from condmon.monitor.forecast import MIN_TESTS, Forecast, fleet_prior, forecast_series
from condmon.simulate import load_actuator_rig, simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.demo import load_demo_config
from condmon.workflows.forecasting import forecast_unit
from condmon.workflows.monitoring import add_baseline_tests, current_baseline

R2 = {"R": 40.0, "D": 600.0}
ALPHA, LAMBDAS = 0.2, (0.5, 0.75)
EXP_A = 0.1                 # the exponential wear's scale: factor = 1 + a (exp(r k) - 1)
MAX_CHECKS = 60

Series = tuple[np.ndarray, np.ndarray, np.ndarray, float]


def demo_rig():  # type: ignore[no-untyped-def]
    return dataclasses.replace(load_actuator_rig(), **load_demo_config().get("rig", {}))


def _series(store, unit: str, param: str) -> Series:  # type: ignore[no-untyped-def]
    """The unit's change series of ``param``, as ``forecast_unit`` reads it (tests)."""
    baseline, ids = current_baseline(store, unit)
    i = baseline.parameters.index(param)
    mean, std = baseline.mean[i], baseline.std[i]
    hist = store.history(unit)
    checks = hist[(hist["role"] == "check") & hist["accepted"].astype(bool)
                  & ~hist["excluded"].astype(bool)]
    checks = checks[[j not in ids for j in checks.index]]
    rows = checks[checks[f"{param}_change"].notna()]
    change = rows[f"{param}_change"].to_numpy(dtype=np.float64)
    se = np.nan_to_num(100.0 * rows[f"{param}_se"].to_numpy(dtype=np.float64) / abs(mean))
    return np.arange(1.0, len(rows) + 1.0), change, se, 100.0 * std / abs(mean)


def run_to_failure(rig, n_units: int) -> list[dict[str, Any]]:  # type: ignore[no-untyped-def]
    """Each unit's wear, its stored series of the worn parameter, its life [tests]."""
    units = []
    for u in range(n_units):
        rng = np.random.default_rng(1000 + u)
        param = "D" if u % 2 == 0 else "R"
        shape = "linear" if (u // 2) % 2 == 0 else "exponential"
        life = rng.uniform(12.0, 30.0)        # tests to the true no-go, a real number
        r2 = R2[param] / 100.0
        rate = r2 / life if shape == "linear" else math.log(1.0 + r2 / EXP_A) / life
        names = ["D", "coulomb_friction"] if param == "D" else ["R"]
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(rig, seed=10_000 * u + s)
                                            for s in range(int(rng.integers(3, 6)))])
            end = None
            for k in range(1, MAX_CHECKS + 1):
                f = 1.0 + rate * k if shape == "linear" else 1.0 + EXP_A * math.expm1(rate * k)
                res = check_test(store, "U", simulate_actuator(
                    rig.with_faults([f"{n}=*{f}" for n in names]), seed=10_000 * u + 100 + k))
                if res.status != "retest" and res.percent_change[param] >= R2[param]:
                    end = k
                    break
            series = _series(store, "U", param)
            # the route's own reading of the same series gives the same forecast
            full = next(p.forecast for p in forecast_unit(store, "U").parameters
                        if p.parameter == param)
            own = forecast_series(*series, threshold=R2[param])
            assert own.remaining == full.remaining, (own, full)
        units.append({"unit": u, "param": param, "shape": shape, "rate": rate,
                      "true_life": life, "life": len(series[0]) if end else None,
                      "series": series})
    return units


def _cut(series: Series, t: int) -> Series:
    x, y, se, spread = series
    return x[:t], y[:t], se[:t], spread


def _threshold(change: np.ndarray, param: str) -> float:
    rising = float(np.mean(change[-MIN_TESTS:])) >= 0.0     # as forecast_unit decides
    return R2[param] if rising else -R2[param]


def _score(preds: list[tuple[float, float, float] | None], truths: list[float]) -> dict[str, Any]:
    """α-λ hits, coverage and relative error of (median, low, high) against the truth."""
    hits = cover = 0
    errors = []
    for p, t in zip(preds, truths):
        if p is None or not math.isfinite(p[0]):
            errors.append(math.inf)
            continue
        hits += abs(p[0] - t) <= ALPHA * t
        cover += p[1] <= t <= p[2]
        errors.append(abs(p[0] - t) / t)
    n = len(truths)
    return {"alpha_lambda_percent": 100.0 * hits / n, "coverage_percent": 100.0 * cover / n,
            "median_rel_error": float(np.median(errors)),
            "no_forecast": sum(p is None for p in preds)}


def _peer(series: Series, t: int, param: str) -> tuple[float, float, float] | None:
    """The peer's median RUL and 90 % interval on the first ``t`` tests."""
    from exponential_degradation import ExponentialDegradationModel

    x, y, _, _ = _cut(series, t)
    threshold = 1.0 + R2[param] / 100.0
    model = ExponentialDegradationModel(threshold=threshold)
    signal = np.maximum(1.0 + y / 100.0, 1e-6)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            model.fit(np.log(signal - model.phi), x)
            out = model.predict_rul(confidence_level=0.90)
    except (ValueError, ZeroDivisionError, FloatingPointError):
        return None
    if "warning" in out:
        return None
    lo, hi = out["CI"]
    return float(out["RUL"]), float(lo), float(hi)


def prognostics(units: list[dict[str, Any]], peer: bool) -> dict[str, Any]:
    done = [u for u in units if u["life"] is not None]
    rows, per_unit = [], []
    for lam in LAMBDAS:
        preds: dict[str, list[tuple[float, float, float] | None]] = {
            "condmon": [], "condmon + fleet prior": [], "peer (Gebraeel 2006)": []}
        truths, shapes = [], []
        for u in done:
            t = max(MIN_TESTS, round(lam * u["life"]))
            truth = float(u["life"] - t)
            if truth <= 0:
                continue
            truths.append(truth)
            shapes.append(u["shape"])
            s = _cut(u["series"], t)
            thr = _threshold(s[1], u["param"])
            own = forecast_series(*s, threshold=thr)
            model = own.model if own.model != "no trend" else "linear"
            others = [v["series"] for v in done if v is not u and v["param"] == u["param"]]
            prior = fleet_prior(others, model=model)
            post = forecast_series(*s, threshold=thr, prior=prior)
            preds["condmon"].append(own.remaining)
            preds["condmon + fleet prior"].append(post.remaining)
            if peer:
                preds["peer (Gebraeel 2006)"].append(_peer(u["series"], t, u["param"]))
            per_unit.append({"unit": u["unit"], "lambda": lam, "true_rul": truth,
                             **{k: v[-1] for k, v in preds.items() if v},
                             "model": own.model, "model_with_prior": post.model,
                             "prior": prior.to_dict()})
        for name, p in preds.items():
            for shape in ("all", "linear", "exponential"):
                pick = [i for i, sh in enumerate(shapes) if shape in ("all", sh)]
                if p:
                    rows.append({"lambda": lam, "method": name, "wear": shape,
                                 "units": len(pick), **_score([p[i] for i in pick],
                                                               [truths[i] for i in pick])})
    return {"rows": rows, "per_unit": per_unit}


def _ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for lam in LAMBDAS:
        by = {r["method"]: r for r in rows if r["lambda"] == lam and r["wear"] == "all"}
        peer = by.get("peer (Gebraeel 2006)")
        if peer is None:
            continue
        for name in ("condmon", "condmon + fleet prior"):
            mine = by[name]
            out.append({"lambda": lam, "method": name, **{
                f"{k} ratio": (mine[k] / peer[k] if peer[k] else math.inf)
                for k in ("alpha_lambda_percent", "coverage_percent", "median_rel_error")}})
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--units", type=int, default=30)
    args = ap.parse_args()
    try:
        import exponential_degradation  # noqa: F401
        peer = True
    except ImportError:
        peer = False
        print("note: the peer exponential-degradation-model is not installed: skipped "
              "(pip install exponential-degradation-model)\n")
    t0 = time.perf_counter()
    doc: dict[str, Any] = {}
    with threadpool_limits(limits=1):
        units = run_to_failure(demo_rig(), args.units)
        lives = [u for u in units if u["life"] is not None]
        fleet = [{"unit": u["unit"], "param": u["param"], "shape": u["shape"],
                  "rate": u["rate"], "true_param_life": u["true_life"], "life": u["life"]}
                 for u in units]
        print(table(fleet, f"Run to failure: {len(lives)} of {len(units)} units crossed no-go "
                           f"within {MAX_CHECKS} checks (life: the crossing check)"))
        res = prognostics(units, peer)
        print()
        print(table(res["rows"], f"RUL at λ of each life: α-λ (α = {ALPHA}: median within "
                                 "±20 % of the true RUL), 90 % interval coverage, median "
                                 "relative error [targets: α-λ >= 80 %, coverage 80-97 %]"))
        ratios = _ratios(res["rows"])
        if ratios:
            print()
            print(table(ratios, "condmon / peer"))
        doc["run_to_failure"] = {"units": fleet, "scores": res["rows"], "ratios": ratios,
                                 "per_unit": res["per_unit"], "peer": peer}
    doc["seconds"] = time.perf_counter() - t0
    path = write_json("bench_prognostics", doc)
    print(f"\nwrote {path} ({doc['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
