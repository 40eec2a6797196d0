"""Prognostics on simulated fleets with known truth (the actuator, nonlinear effects on).

    python benchmarks/bench_prognostics.py [--units 30] [--first 0] [--fleets 5]
                                           [--only rtf|calibration|drift]
    pip install exponential-degradation-model   # the peer (optional; skipped with a note)

1. Run to failure. Each unit wears one parameter (friction D with the Coulomb
   friction alike, or the winding resistance R), linearly (``1 + r·k``) or
   exponentially (``1 + 0.1·(exp(r·k) − 1)``), at a rate drawn so that the true
   parameter reaches r2 (R +40 %, D +600 %) after 12-30 tests.
   A 3-5 test healthy baseline, then checks (simulate, ``check_test`` into an
   in-memory store) until a check turns no-go: that test is the unit's end of
   life (short of r2: where the worn parameter's symptom reaches the
   diagnoser's no-go degree, ``NoGo``). The forecasts are made on the stored
   series (read as ``forecast_unit`` reads it, to the no-go change it takes,
   counted in tests, so in whole checks: the first check whose measured
   change passes it; checked against it on the full series) cut at
   λ = 0.5 and 0.75 of each life, and scored by the α-λ accuracy (α = 0.2: the
   share of units whose median RUL is within ±20 % of the true RUL), the
   coverage of the 90 % interval, and the median relative error. An interval
   in whole checks cannot hold exactly 90 % (a check count cannot split): its
   ends are the mid-p quantiles, which hold 90 % on average, more or less for
   one forecast (84-100 %); the randomised PIT's central 90 % coverage (the truth's place in
   the forecast's distribution, a tie spread uniformly) takes that
   discreteness out and is the calibration proper. Again with the
   fleet prior (leave-one-out: from the other units that wore the same
   parameter, their full series: the share that wore exponentially, the
   linear slope and the exponential growth rate, as ``condmon forecast``
   takes it from a unit's degraded peers), and with the peer
   ``exponential-degradation-model`` (Gebraeel 2006, as
   MATLAB's exponentialDegradationModel) fed the same series as
   ``ln(S − φ)`` of the signal ``S = 1 + change/100`` (its default φ = −1 and
   vague priors), the threshold ``1 + r2/100``. A reference row scores the
   true parameter's own crossing (``true_param_life`` less the cut): what
   a forecaster who knew each unit's wear exactly would say, against the
   check whose noisy estimate first crossed; its misses show how much of
   the ±20 % the estimates' scatter and bias and the checks' spacing take
   (a forecast of the estimates, bias and all, can do better). ``--fleets
   K`` (5 by default) runs K fleets, each with seeds of its own, and scores
   each and all of them pooled: the fleets after the first are held out
   from whatever the method was tuned on. 30 units give a coverage to ±5 %
   (binomial sd at 90 %): one fleet at 100 % is what 92 %-content intervals
   give one time in 12, so the pooled 150 units are the figure to read.

2. Calibration. Healthy units (each its own 10-test baseline, then 20
   checks) at alpha = 0.01: the observed false-alarm rate of the statistical
   detector's level alarm and drift alarm (per check, where defined), with a
   95 % Clopper-Pearson interval and the ratio to alpha; and the fuzzy
   status's (not "go") on the same checks.
3. Drift delay. Friction rises +4 % a test (D and the Coulomb friction
   ×(1 + 0.04·k)): the first alarming check of the level statistic, the drift
   statistic, either, and the fuzzy status (advisory or worse), at matched
   false-alarm rates (the statistical alpha set to the fuzzy status's observed
   rate, or its 95 % upper bound when that is 0).
   Sections 2 and 3 need the calibrated detector (``CheckResult.statistics``);
   without it they are skipped with a note.

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
from condmon.forecast.series import MIN_TESTS, fleet_wear_prior, forecast_series
from condmon.models.registry import get_model
from condmon.forecast.unit import NoGo
from condmon.simulate import load_actuator_rig, simulate_actuator
from condmon.store import open_store
from condmon.store.forecasts import machine_nogo
from condmon.workflows.checks import check_test
from condmon.workflows.demo import load_demo_config
from condmon.workflows.forecasting import forecast_unit
from condmon.workflows.monitoring import add_baseline_tests, current_baseline

R2 = {"R": 40.0, "D": 600.0}
CAL_UNITS, CAL_CHECKS, CAL_BASELINE, CAL_ALPHA = 100, 20, 10, 0.01
DRIFT_UNITS, DRIFT_RATE, DRIFT_MAX = 20, 0.04, 90
ALPHA, LAMBDAS = 0.2, (0.5, 0.75)
EXP_A = 0.1                 # the exponential wear's scale: factor = 1 + a (exp(r k) - 1)
MAX_CHECKS = 60
SECTIONS = ("rtf", "calibration", "drift")
#: Run-to-failure fleets of the default run (each of --units, seeds of its own).
FLEETS = 5
#: The reference row: the true parameter's own crossing, against the check that saw it.
REFERENCE = "true wear's crossing (reference)"

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


def run_to_failure(rig, n_units: int,  # type: ignore[no-untyped-def]
                   first: int = 0) -> list[dict[str, Any]]:
    """Each unit's wear, its stored series of the worn parameter, its life [tests]
    (units ``first`` to ``first + n_units - 1``: each its own seeds)."""
    units = []
    for u in range(first, first + n_units):
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
                if res.status == "no-go":        # the check that turned no-go ends its life
                    end = k
                    break
            series = _series(store, "U", param)
            nogo = machine_nogo(get_model(store.unit_model("U") or "dc-motor"),
                                current_baseline(store, "U")[0])[0][param]
            # the route's own reading of the same series gives the same forecast
            full = next(p.forecast for p in forecast_unit(store, "U").parameters
                        if p.parameter == param)
            own = forecast_series(*series, threshold=nogo.threshold(*series)[0], step=1.0)
            assert own.remaining == full.remaining, (own, full)
        # the true parameter's crossing of the change its checks turn no-go at
        at = abs(nogo.threshold(*series)[0]) / 100.0
        true_life = at / rate if shape == "linear" else math.log1p(at / EXP_A) / rate
        units.append({"unit": u, "param": param, "shape": shape, "rate": rate,
                      "true_life": true_life, "life": len(series[0]) if end else None,
                      "series": series, "nogo": nogo})
    return units


def _cut(series: Series, t: int) -> Series:
    x, y, se, spread = series
    return x[:t], y[:t], se[:t], spread


def _threshold(series: Series, nogo: NoGo) -> float:
    """The no-go change the series heads for, as ``forecast_unit`` takes it. [%]"""
    return nogo.threshold(*series)[0]


def _pit(series: Series, threshold: float, prior: Any, truth: float) -> tuple[float, float]:
    """The forecast's P(T < truth) and P(T <= truth) (the same draws: the
    forecast's fixed seed), for the randomised PIT of a whole-check truth."""
    def within(h: float) -> float:
        if h <= 0:
            return 0.0
        p = forecast_series(*series, threshold=threshold, prior=prior, step=1.0,
                            horizon=h).p_within
        return float(p) if p is not None else math.nan
    return within(truth - 1.0), within(truth)


def _pit_cover(below: float, upto: float) -> float:
    """The chance that the randomised PIT ``below + U·(upto − below)`` falls in
    the central 90 % [0.05, 0.95] (U uniform): the 90 % interval's coverage
    with the whole checks' discreteness taken out."""
    if upto <= below:
        return float(0.05 <= below <= 0.95)
    return max(0.0, min(upto, 0.95) - max(below, 0.05)) / (upto - below)


def _score(preds: list[tuple[float, ...] | None], truths: list[float]) -> dict[str, Any]:
    """α-λ hits, coverage and relative error of (median, low, high) against the
    truth; with (P(T < truth), P(T <= truth)) after them, the randomised PIT's
    central 90 % coverage too."""
    hits = cover = 0
    errors, pits = [], []
    for p, t in zip(preds, truths):
        if p is None or not math.isfinite(p[0]):
            errors.append(math.inf)
            continue
        hits += abs(p[0] - t) <= ALPHA * t
        cover += p[1] <= t <= p[2]
        errors.append(abs(p[0] - t) / t)
        if len(p) == 5:
            pits.append(_pit_cover(p[3], p[4]))
    n = len(truths)
    return {"alpha_lambda_percent": 100.0 * hits / n, "coverage_percent": 100.0 * cover / n,
            "pit_coverage_percent": 100.0 * float(np.mean(pits)) if pits else "-",
            "median_rel_error": float(np.median(errors)),
            "no_forecast": sum(p is None for p in preds)}


def _peer(series: Series, t: int, thr: float) -> tuple[float, float, float] | None:
    """The peer's median RUL and 90 % interval on the first ``t`` tests, to
    the no-go change ``thr`` [%]."""
    from exponential_degradation import ExponentialDegradationModel

    x, y, _, _ = _cut(series, t)
    threshold = 1.0 + thr / 100.0
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
        preds: dict[str, list[tuple[float, ...] | None]] = {
            REFERENCE: [], "condmon, no prior": [], "condmon, fleet prior (leave-one-out)": [],
            "peer (Gebraeel 2006)": []}
        truths, shapes = [], []
        for u in done:
            t = max(MIN_TESTS, round(lam * u["life"]))
            truth = float(u["life"] - t)
            if truth <= 0:
                continue
            truths.append(truth)
            shapes.append(u["shape"])
            s = _cut(u["series"], t)
            thr = _threshold(s, u["nogo"])
            own = forecast_series(*s, threshold=thr, step=1.0)
            others = [v["series"] for v in done if v is not u and v["param"] == u["param"]]
            prior = fleet_wear_prior(others)
            post = forecast_series(*s, threshold=thr, prior=prior, step=1.0)
            # what a forecaster who knew the true wear would say: the true
            # parameter's crossing, a point (no interval)
            preds[REFERENCE].append((u["true_life"] - t, math.nan, math.nan))
            for name, f, pr in (("condmon, no prior", own, None),
                                ("condmon, fleet prior (leave-one-out)", post, prior)):
                preds[name].append(None if f.remaining is None else
                                   (*f.remaining, *_pit(s, thr, pr, truth)))
            if peer:
                preds["peer (Gebraeel 2006)"].append(_peer(u["series"], t, thr))
            per_unit.append({"unit": u["unit"], "lambda": lam, "true_rul": truth,
                             **{k: v[-1] for k, v in preds.items() if v},
                             "model": own.model, "model_with_prior": post.model,
                             "prior": prior.to_dict()})
        for name, p in preds.items():
            for shape in ("all", "linear", "exponential"):
                pick = [i for i, sh in enumerate(shapes) if shape in ("all", sh)]
                if p and pick:
                    scores = _score([p[i] for i in pick], [truths[i] for i in pick])
                    if name == REFERENCE:
                        scores["coverage_percent"] = "-"
                    rows.append({"lambda": lam, "method": name, "wear": shape,
                                 "units": len(pick), **scores})
    return {"rows": rows, "per_unit": per_unit}


def _ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for lam in LAMBDAS:
        by = {r["method"]: r for r in rows if r["lambda"] == lam and r["wear"] == "all"}
        peer = by.get("peer (Gebraeel 2006)")
        if peer is None:
            continue
        for name in ("condmon, no prior", "condmon, fleet prior (leave-one-out)"):
            mine = by[name]
            out.append({"lambda": lam, "method": name, **{
                f"{k} ratio": (mine[k] / peer[k] if peer[k] else math.inf)
                for k in ("alpha_lambda_percent", "coverage_percent", "median_rel_error")}})
    return out


def _statistics_config():  # type: ignore[no-untyped-def]
    """The detector's settings class, or None before the detector exists."""
    try:
        from condmon.monitor.statistics import StatisticsConfig
    except ImportError:
        return None
    return StatisticsConfig


def _monitor(store, alpha: float):  # type: ignore[no-untyped-def]
    from condmon.workflows.monitoring import unit_monitor

    cfg = unit_monitor(store, "U", current_baseline(store, "U")[0])
    return dataclasses.replace(cfg, statistics=_statistics_config()(alpha=alpha, drift_alpha=alpha))


def _rate(k: int, n: int) -> dict[str, Any]:
    """Rate and 95 % Clopper-Pearson interval of k events in n."""
    from scipy.stats import beta

    lo = float(beta.ppf(0.025, k, n - k + 1)) if k else 0.0
    hi = float(beta.ppf(0.975, k + 1, n - k)) if k < n else 1.0
    return {"checks": n, "alarms": k, "rate": k / n if n else math.nan, "low95": lo, "high95": hi}


def calibration(rig, n_units: int) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    level, drift, fuzzy = [], [], []
    for u in range(n_units):
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(rig, seed=500_000 + 100 * u + i)
                                            for i in range(CAL_BASELINE)])
            cfg = _monitor(store, CAL_ALPHA)
            for k in range(CAL_CHECKS):
                res = check_test(store, "U", simulate_actuator(rig, seed=600_000 + 100 * u + k),
                                 monitor=cfg)
                if res.status == "retest":
                    continue
                fuzzy.append(res.status != "go")
                st = res.statistics
                if st is None:
                    continue
                if st.alarm is not None:
                    level.append(bool(st.alarm))
                if st.drift_alarm is not None:
                    drift.append(bool(st.drift_alarm))
    rows = []
    for name, hits, alpha in (("level alarm", level, CAL_ALPHA), ("drift alarm", drift, CAL_ALPHA),
                              ("fuzzy status != go", fuzzy, None)):
        r = _rate(sum(hits), len(hits))
        rows.append({"detector": name, "alpha": alpha if alpha else "-", **r,
                     "rate/alpha": r["rate"] / alpha if alpha else "-"})
    return {"rows": rows}


def drift_delay(rig, n_units: int, alpha: float) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    firsts: dict[str, list[float]] = {"level": [], "drift": [], "level or drift": [], "fuzzy": []}
    for u in range(n_units):
        seen: dict[str, float] = {}
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(rig, seed=700_000 + 100 * u + i)
                                            for i in range(CAL_BASELINE)])
            cfg = _monitor(store, alpha)
            for k in range(1, DRIFT_MAX + 1):
                f = 1.0 + DRIFT_RATE * k
                res = check_test(store, "U", simulate_actuator(
                    rig.with_faults([f"D=*{f}", f"coulomb_friction=*{f}"]),
                    seed=800_000 + 100 * u + k), monitor=cfg)
                st = res.statistics
                flags = {"fuzzy": res.status in ("advisory", "no-go"),
                         "level": bool(st and st.alarm), "drift": bool(st and st.drift_alarm)}
                flags["level or drift"] = flags["level"] or flags["drift"]
                for name, on in flags.items():
                    if on and name not in seen:
                        seen[name] = k
                if len(seen) == len(firsts):
                    break
        for name in firsts:
            firsts[name].append(seen.get(name, math.inf))
    rows = []
    fuzzy_med = float(np.median(firsts["fuzzy"]))
    for name, v in firsts.items():
        med = float(np.median(v))
        rows.append({"detector": name, "alpha": alpha if name != "fuzzy" else "-",
                     "median_delay": med, "min": float(min(v)), "max": float(max(v)),
                     "undetected": sum(not math.isfinite(d) for d in v),
                     "earlier_than_fuzzy_percent": 100.0 * (1.0 - med / fuzzy_med)
                     if name != "fuzzy" else 0.0})
    return {"rows": rows, "delays": {k: [d if math.isfinite(d) else None for d in v]
                                     for k, v in firsts.items()}}


def _rtf_section(n_units: int, peer: bool, first: int = 0) -> dict[str, Any]:
    units = run_to_failure(demo_rig(), n_units, first)
    lives = [u for u in units if u["life"] is not None]
    fleet = [{"unit": u["unit"], "param": u["param"], "shape": u["shape"],
              "rate": u["rate"], "true_param_life": u["true_life"], "life": u["life"]}
             for u in units]
    print(table(fleet, f"Run to failure: {len(lives)} of {len(units)} units crossed no-go "
                       f"within {MAX_CHECKS} checks (life: the crossing check)"))
    res = prognostics(units, peer)
    print()
    print(table(res["rows"], f"RUL at λ of each life: α-λ (α = {ALPHA}: median within "
                             "±20 % of the true RUL), 90 % interval coverage (whole checks: "
                             "mid-p ends), the randomised PIT's central "
                             "90 % coverage (the same calibration, the checks' discreteness "
                             "taken out), median relative error [targets: α-λ >= 80 %, "
                             "coverage 80-97 %]"))
    ratios = _ratios(res["rows"])
    if ratios:
        print()
        print(table(ratios, "condmon / peer"))
    return {"units": fleet, "scores": res["rows"], "ratios": ratios,
            "per_unit": res["per_unit"], "peer": peer}


def _fleets_summary(fleets: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each fleet's and the pooled α-λ and coverage, per method and λ."""
    rows = []
    methods = [m for m in ("condmon, no prior", "condmon, fleet prior (leave-one-out)",
                           "peer (Gebraeel 2006)") if any(m in r for f in fleets
                                                           for r in f["per_unit"])]
    for lam in LAMBDAS:
        for name in methods:
            for f in fleets + [None]:   # None: all of them
                per = ([r for g in fleets for r in g["per_unit"]] if f is None
                       else f["per_unit"])
                pick = [r for r in per if r["lambda"] == lam and name in r]
                sc = _score([tuple(r[name]) if r[name] is not None else None for r in pick],
                            [r["true_rul"] for r in pick])
                rows.append({"lambda": lam, "method": name,
                             "fleet": "pooled" if f is None else f"from {f['first']}",
                             "units": len(pick), **sc})
    return rows


def _detector_sections(cal_units: int, drift_units: int) -> dict[str, Any]:
    cal = calibration(demo_rig(), cal_units)
    print()
    print(table(cal["rows"], f"Calibration: {cal_units} healthy units × "
                             f"{CAL_CHECKS} checks, own {CAL_BASELINE}-test baselines; "
                             "false-alarm rate per check, 95 % interval [target "
                             "rate/alpha 0.5-2]"))
    fuzzy = next(r for r in cal["rows"] if r["detector"].startswith("fuzzy"))
    matched = fuzzy["rate"] if fuzzy["alarms"] else fuzzy["high95"]
    how = ("the fuzzy status's observed false-alarm rate" if fuzzy["alarms"]
           else "the 95 % upper bound of the fuzzy status's false-alarm rate (0 seen)")
    dd = drift_delay(demo_rig(), drift_units, matched)
    print()
    print(table(dd["rows"], f"Drift delay: friction +{100 * DRIFT_RATE:g} % a test, "
                            f"{drift_units} units; first alarming check; "
                            f"alpha = {matched:.4g} ({how}) [goal: >= 30 % earlier]"))
    return {"calibration": cal, "drift": {**dd, "alpha": matched, "alpha_is": how}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--units", type=int, default=30)
    ap.add_argument("--first", type=int, default=0,
                    help="the first run-to-failure unit (its seeds): another fleet of as many")
    ap.add_argument("--fleets", type=int, default=FLEETS,
                    help="run-to-failure fleets, each of --units with seeds of its own "
                         "(from --first on), scored each and pooled")
    ap.add_argument("--cal-units", type=int, default=CAL_UNITS)
    ap.add_argument("--drift-units", type=int, default=DRIFT_UNITS)
    ap.add_argument("--only", choices=SECTIONS, action="append",
                    help="run only this section (repeatable; default: all; drift runs the "
                         "calibration too: its alpha is the fuzzy status's rate there)")
    args = ap.parse_args()
    only = set(args.only or SECTIONS)
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
        if "rtf" in only:
            fleets = []
            for k in range(args.fleets):
                first = args.first + k * args.units
                if args.fleets > 1:
                    print(f"\n== fleet of units {first}-{first + args.units - 1}")
                fleets.append({"first": first, **_rtf_section(args.units, peer, first)})
            doc["run_to_failure"] = fleets[0] if len(fleets) == 1 else {"fleets": fleets}
            if len(fleets) > 1:
                summary = _fleets_summary(fleets)
                doc["run_to_failure"]["summary"] = summary
                print()
                print(table(summary, f"{len(fleets)} fleets of {args.units} units: α-λ and "
                                     "90 % interval coverage, each and pooled"))
        if only & {"calibration", "drift"}:
            if _statistics_config() is None:
                print("\nnote: no calibrated statistical detector (condmon.monitor.statistics) "
                      "in this condmon: calibration and drift delay skipped")
            else:   # the drift section's alpha is the calibration's fuzzy rate: both run
                doc.update(_detector_sections(args.cal_units, args.drift_units))
    doc["seconds"] = time.perf_counter() - t0
    name = "bench_prognostics" if only == set(SECTIONS) else \
        "bench_prognostics_" + "_".join(k for k in SECTIONS if k in only)
    if args.first:
        name += f"_from{args.first}"
    if args.fleets != FLEETS:
        name += f"_x{args.fleets}"
    path = write_json(name, doc)
    print(f"\nwrote {path} ({doc['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
