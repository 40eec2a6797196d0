"""Prognostics on real run-to-failure data: NASA's Li-ion cells, side by side with peers.

    python benchmarks/bench_prognostics_real.py [--data DIR] [--every 5] [--start 0.3]

The cells B0005, B0006, B0007 and B0018 (``../shared/external/batteries/nasa/``,
one ``cycle,capacity`` table each) were cycled until their capacity fell 30 %,
from 2 Ah to 1.4 Ah. End of life, as that data set's README states it: the
first cycle below 1.4 Ah (B0007 never gets there: 1.5 Ah). The true remaining
life at cycle k is that cycle less k.

Rolling forecasts from 30 % of each cell's life on, every 5th cycle, each
from the cycles up to it only, by:

- **condmon**: :func:`condmon.forecast.series.forecast_series` on the change
  of capacity against a healthy baseline (the first 5 cycles: their mean and
  standard deviation, which is also each cycle's standard error: the data
  give none), to the change that is the end of life; whole cycles (``step=1``).
  This is what a user gets today by making one check per cycle.
- **condmon, Wiener path** (:mod:`condmon.forecast.wiener`, not yet what
  ``condmon forecast`` gives): the capacity as a Wiener process with drift,
  fitted to every cycle so far, its first passage of the end-of-life level
  (inverse Gaussian), with the drift's and diffusion's uncertainty drawn.
- **a straight line**: least squares of capacity on cycle over every cycle so
  far, its crossing of the end-of-life level, the 90 % interval from the
  coefficients' covariance and the residuals' scatter (5 % and 95 % points of
  4,000 draws of the cycle a measurement first reads below the level).
- **NASA ProgPy**: not run here unless installed (``pip install progpy``); its
  figures on the same 77 points, as measured when these cells were added
  (the data set's README), are printed as published figures.

Printed, per method: the 90 % interval's coverage of the true remaining life,
α-λ accuracy (α = 0.2: the share of forecasts whose median lies within ±20 %
of the true remaining life) at λ = 0.5 and 0.75 of each life (the forecast
nearest each) and over every rolling forecast, the median interval width
relative to the true remaining life, and the share of forecasts that came too
early (median below the truth). Nothing here is tuned to these cells: the
settings are the forecast's defaults, the same for every cell.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import table, write_json  # noqa: E402

from condmon.errors import CondmonError  # noqa: E402
from condmon.forecast.series import forecast_series  # noqa: E402
from condmon.forecast.wiener import wiener_forecast  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "external" / "batteries" / "nasa"
#: End of life per cell [Ah] (the data set's README).
EOL = {"B0005": 1.4, "B0006": 1.4, "B0007": 1.5, "B0018": 1.4}
BASELINE = 5          # healthy cycles that make the baseline
ALPHA = 0.2           # the α of α-λ
#: ProgPy 1.9 (Kalman filter + Monte Carlo) on these cells and points, as measured
#: when they were added (../shared/external/batteries/README.md).
PROGPY = {"coverage": 0.84, "alpha_lambda_rolling": 0.31}


def read_cell(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A cell's ``cycle`` and ``capacity`` columns. [-, Ah]"""
    data = np.genfromtxt(path, delimiter=",", names=True)
    return np.asarray(data["cycle"], dtype=np.float64), np.asarray(data["capacity"],
                                                                   dtype=np.float64)


def end_of_life(cycle: np.ndarray, capacity: np.ndarray, level: float) -> float:
    """The first cycle whose capacity is below ``level``."""
    below = np.flatnonzero(capacity < level)
    return float(cycle[below[0]]) if below.size else float(cycle[-1])


def condmon_forecast(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float
                     ) -> tuple[float, float, float] | None:
    """condmon's remaining cycles (median, 5 %, 95 %) from the cycles up to index ``k``."""
    base = capacity[:BASELINE]
    mean, std = float(base.mean()), float(base.std(ddof=1))
    spread = 100.0 * std / mean
    x = cycle[BASELINE:k + 1]
    change = 100.0 * (capacity[BASELINE:k + 1] - mean) / mean
    threshold = 100.0 * (level - mean) / mean
    try:
        f = forecast_series(x, change, np.full(x.size, spread), spread, threshold, step=1.0)
    except CondmonError:
        return None
    return None if f.remaining is None else tuple(map(float, f.remaining))  # type: ignore[return-value]


def wiener_row(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float
               ) -> tuple[float, float, float] | None:
    """The Wiener-path model's remaining cycles (median, 5 %, 95 %) from the cycles
    up to ``k`` (:func:`condmon.forecast.wiener.wiener_forecast`, to the absolute level)."""
    try:
        return wiener_forecast(cycle[:k + 1], capacity[:k + 1], level, seed=k).remaining
    except CondmonError:
        return None


def line_forecast(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float,
                  rng: np.random.Generator) -> tuple[float, float, float] | None:
    """A straight line's remaining cycles (median, 5 %, 95 %) from the cycles up to ``k``."""
    x, y = cycle[:k + 1], capacity[:k + 1]
    a = np.column_stack([np.ones_like(x), x])
    coef, res, *_ = np.linalg.lstsq(a, y, rcond=None)
    dof = max(x.size - 2, 1)
    s2 = float(np.sum((y - a @ coef) ** 2)) / dof
    cov = s2 * np.linalg.inv(a.T @ a)
    draws = rng.multivariate_normal(coef, cov, 4000)
    # the measured capacity's own scatter about the line: the cycle a measurement
    # first reads below the level, not the line's crossing alone
    noise = rng.normal(0.0, math.sqrt(s2), 4000)
    falling = draws[:, 1] < 0
    cross = np.where(falling, (level - noise - draws[:, 0])
                     / np.where(falling, draws[:, 1], 1.0), np.inf)
    left = np.maximum(cross - x[-1], 0.0)
    return (float(np.median(left)), float(np.quantile(left, 0.05)),
            float(np.quantile(left, 0.95)))


def score(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Coverage, α-λ (rolling, λ 0.5, 0.75), relative width and early share of forecasts."""
    done = [r for r in rows if r["forecast"] is not None]
    if not done:
        return {"forecasts": 0}
    truth = np.array([r["truth"] for r in done])
    med = np.array([r["forecast"][0] for r in done])
    lo = np.array([r["forecast"][1] for r in done])
    hi = np.array([r["forecast"][2] for r in done])
    within = np.abs(med - truth) <= ALPHA * truth

    def at(lam: float) -> float:
        picks = []
        for cell in sorted({r["cell"] for r in done}):
            mine = [i for i, r in enumerate(done) if r["cell"] == cell]
            target = lam * done[mine[0]]["life"]
            picks.append(min(mine, key=lambda i: abs(done[i]["cycle"] - target)))
        return float(np.mean(within[picks]))

    width = np.where(np.isfinite(hi - lo), (hi - lo) / truth, np.inf)
    return {"forecasts": len(done), "missing": len(rows) - len(done),
            "coverage": float(np.mean((lo <= truth) & (truth <= hi))),
            "alpha_lambda_rolling": float(np.mean(within)),
            "alpha_lambda_0.5": at(0.5), "alpha_lambda_0.75": at(0.75),
            "median_relative_width": float(np.median(width)),
            "too_early": float(np.mean(med < truth))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--every", type=int, default=5, help="cycles between forecasts")
    ap.add_argument("--start", type=float, default=0.3, help="first forecast, fraction of life")
    args = ap.parse_args()
    if not args.data.is_dir():
        sys.exit(f"{args.data}: no such folder (give --data DIR with B0005.csv ...)")
    load = os.getloadavg()
    rng = np.random.default_rng(0)
    rows: dict[str, list[dict[str, Any]]] = {"condmon": [], "condmon Wiener path": [],
                                             "straight line": []}
    started = time.perf_counter()
    for cell, level in EOL.items():
        cycle, capacity = read_cell(args.data / f"{cell}.csv")
        life = end_of_life(cycle, capacity, level)
        first = math.ceil(args.start * life)
        for c in np.arange(first, life, args.every):
            k = int(np.searchsorted(cycle, c))
            truth = life - float(cycle[k])
            common = {"cell": cell, "cycle": float(cycle[k]), "life": life, "truth": truth}
            rows["condmon"].append({**common, "forecast": condmon_forecast(
                cycle, capacity, k, level)})
            rows["condmon Wiener path"].append({**common, "forecast": wiener_row(
                cycle, capacity, k, level)})
            rows["straight line"].append({**common, "forecast": line_forecast(
                cycle, capacity, k, level, rng)})
    elapsed = time.perf_counter() - started
    scores = [{"method": m, **score(r)} for m, r in rows.items()]
    scores.append({"method": "ProgPy 1.9 (published, same points)", "forecasts": 77,
                   "missing": 0, "coverage": PROGPY["coverage"],
                   "alpha_lambda_rolling": PROGPY["alpha_lambda_rolling"],
                   "alpha_lambda_0.5": math.nan, "alpha_lambda_0.75": math.nan,
                   "median_relative_width": math.nan, "too_early": math.nan})
    keys = ["method", "forecasts", "missing", "coverage", "alpha_lambda_rolling",
            "alpha_lambda_0.5", "alpha_lambda_0.75", "median_relative_width", "too_early"]
    shown = [{k: s.get(k, math.nan) for k in keys} for s in scores]
    print(table(shown, f"NASA Li-ion cells, rolling forecasts every {args.every} cycles from "
                       f"{args.start:.0%} of life (load {load[0]:.2f} {load[1]:.2f} "
                       f"{load[2]:.2f}; {elapsed:.1f} s)"))
    best = max(s["alpha_lambda_rolling"] for s in scores[2:])
    for ours in scores[:2]:
        print(f"\n{ours['method']} / best peer, rolling α-λ: "
              f"{ours['alpha_lambda_rolling'] / best:.2f}; coverage (target 0.80-0.97): "
              f"{ours['coverage']:.2f}", end="")
    print()
    path = write_json("prognostics_real", {"load": load, "seconds": elapsed, "scores": scores,
                                           "forecasts": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
