"""Prognostics on real run-to-failure data: NASA's Li-ion cells, side by side with peers.

    python benchmarks/bench_prognostics_real.py [--data DIR] [--level 1.4]
                                                [--level-for B0007=1.5] [--every 5] [--start 0.3]
                                                [--draw-sets 5] [--no-progpy]
    pip install '.[bench]'      # ProgPy (and SIPPY): the peer is skipped with a note without it

The cells B0005, B0006, B0007 and B0018 (``../shared/external/batteries/nasa/``,
one ``cycle,capacity`` table each) were cycled until their capacity fell 30 %,
from 2 Ah to 1.4 Ah. End of life, as that data set's README states it: the
first cycle below 1.4 Ah (B0007 never gets there: 1.5 Ah). The true remaining
life at cycle k is that cycle less k. Another data set: ``--data DIR`` (every
``*.csv`` in it, each a unit's ``cycle,capacity``), ``--level`` its README's
end of life and ``--level-for CELL=LEVEL`` its exceptions.

Rolling forecasts from 30 % of each cell's life on, every 5th cycle, each
from the cycles up to it only, by:

- **condmon**: what ``condmon import`` then ``condmon forecast`` give with the
  shipped declaration ``examples/batteries/li-ion-18650.toml`` (its method
  "path", :func:`condmon.forecast.measured.forecast_path`): the capacity's
  change against the baseline of the first 5 cycles, to the end of life's
  change, in whole cycles.
- **condmon, recalibrated on the other cells**: the same forecast read at
  the levels where the other cells' true lives fell in their own forecasts
  (leave-one-out: each cell's peers are the other cells; Kuleshov, Fenner
  and Ermon 2018), with the other cells' whole lives as its prior: their
  rates' wander pooled with its own, the rates at which they went on from as
  near their ends as it is weighed against its own rate now
  (:func:`condmon.forecast.path.with_fleet`), and the cycles they had left
  from there a share of its draws, the share that scored best along their
  own series (:mod:`condmon.forecast.similar`): what the fleet's failed
  units change.
- **condmon, trend method**: the line or exponential chosen by evidence
  (:func:`condmon.forecast.series.forecast_series`), what estimated
  parameters are forecast with.
- **a straight line**: least squares of capacity on cycle over every cycle so
  far, its crossing of the end-of-life level, the 90 % interval from the
  coefficients' covariance and the residuals' scatter (5 % and 95 % points of
  4,000 draws of the cycle a measurement first reads below the level).
- **NASA ProgPy 1.9** (``_progpy_peer.py``, when installed): a linear fade
  with a random-walk rate, its Kalman filter, then Monte Carlo to the event.
- **ProgPy, published**: the figures the data set's README gives for these
  cells (its own run: 77 forecasts).

Printed, per method: the 90 % interval's coverage of the true remaining life,
α-λ accuracy (α = 0.2: the share of forecasts whose median lies within ±20 %
of the true remaining life) at λ = 0.5 and 0.75 of each life (the forecast
nearest each) and over every rolling forecast, the median interval width
relative to the true remaining life, and the share of forecasts that came too
early (median below the truth). Nothing here is tuned to these cells: the
settings are the forecast's defaults, the same for every cell.

condmon's path rows are Monte-Carlo figures. The table gives the seeds
``condmon forecast`` uses; a second table repeats both rows with
``--draw-sets`` sets of draws (the forecasts' and their peers') and gives
each figure's median, lowest and highest, so a ratio to a peer is read with
its Monte-Carlo spread.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import table, write_json  # noqa: E402

from condmon.errors import CondmonError  # noqa: E402
from condmon.forecast.measured import forecast_path  # noqa: E402
from condmon.forecast.calibration import (  # noqa: E402
    MIN_PEERS, Calibration, calibrate, life_of, path_scores)
from condmon.forecast.path import Life  # noqa: E402
from condmon.forecast.series import forecast_series  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "external" / "batteries" / "nasa"
#: End of life per cell [Ah] (the NASA data set's README).
EOL = {"B0005": 1.4, "B0006": 1.4, "B0007": 1.5, "B0018": 1.4}
BASELINE = 5          # healthy cycles that make the baseline (condmon import's default)
ALPHA = 0.2           # the α of α-λ
#: Seeds of one Monte-Carlo draw set from the next (a prime, past any cycle count).
SEED_STRIDE = 7919
#: condmon's rows whose Monte-Carlo spread is measured over ``--draw-sets``.
PATH_METHODS = ("condmon", "condmon, recalibrated on the other cells")
#: ProgPy 1.9 (Kalman filter + Monte Carlo) on these cells, as the data set's README
#: gives it (../shared/external/batteries/README.md: its own run, 77 forecasts).
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


def _change(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float
            ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The checks after the baseline up to ``k``: x, change [%], the baseline's
    spread [%] and the end of life's change [%]."""
    base = capacity[:BASELINE]
    mean, std = float(base.mean()), float(base.std(ddof=1))
    x = cycle[BASELINE:k + 1]
    return (x, 100.0 * (capacity[BASELINE:k + 1] - mean) / mean, 100.0 * std / mean,
            100.0 * (level - mean) / mean)


def condmon_row(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float,
                levels: Calibration | None = None, draw_set: int = 0
                ) -> tuple[float, float, float] | None:
    """condmon's remaining cycles (median, 5 %, 95 %) from the cycles up to index
    ``k``, as ``condmon forecast`` gives them after ``condmon import``; read at
    ``levels`` when recalibrated on the fleet's failed units. ``draw_set`` 0
    is the seed ``condmon forecast`` uses; others give other Monte-Carlo draws."""
    x, change, spread, threshold = _change(cycle, capacity, k, level)
    try:
        f = forecast_path(x, change, np.zeros(x.size), spread, threshold, step=1.0,
                          seed=k + SEED_STRIDE * draw_set, calibration=levels)
    except CondmonError:
        return None
    return f.remaining


def trend_row(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float
              ) -> tuple[float, float, float] | None:
    """condmon's trend method (a line or an exponential), the same series."""
    x, change, spread, threshold = _change(cycle, capacity, k, level)
    try:
        f = forecast_series(x, change, np.full(x.size, spread), spread, threshold, step=1.0)
    except CondmonError:
        return None
    return f.remaining


def _to_end(cycle: np.ndarray, capacity: np.ndarray, level: float
            ) -> tuple[np.ndarray, np.ndarray, float]:
    """A failed peer's change series up to its end of life, and that life's change."""
    end = int(np.searchsorted(cycle, end_of_life(cycle, capacity, level)))
    x, change, _, threshold = _change(cycle, capacity, end, level)
    return x, change, threshold


def peer_pits(cycle: np.ndarray, capacity: np.ndarray, level: float, draw_set: int = 0,
              lives: tuple[Life, ...] = ()) -> list[tuple[float, float, float, float]]:
    """Where a failed peer's true remaining life fell in condmon's forecasts
    along its series, and in its fleet's remaining lives, as ``condmon
    forecast`` reads its peers (:func:`condmon.forecast.calibration.path_scores`),
    the other peers' ``lives`` as each forecast's prior and fleet."""
    x, change, threshold = _to_end(cycle, capacity, level)
    return path_scores(x, change, threshold, seed=SEED_STRIDE * draw_set, lives=lives)


def forecast_points(cells: dict[str, tuple[np.ndarray, np.ndarray]], levels: dict[str, float],
                    start: float, every: int, started: float | None = None
                    ) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """Each cell's rolling forecast points: the cell, the index of the last
    cycle used, and the row's common fields (cycle, life, true remaining
    life); a progress line per cell on stderr when ``started`` is given."""
    for cell, (cycle, capacity) in cells.items():
        life = end_of_life(cycle, capacity, levels[cell])
        first = math.ceil(start * life)
        points = np.arange(first, life, every)
        if started is not None:
            print(f"  {cell}: {points.size} forecast points, cycles {first:g}-{life:g} "
                  f"({time.perf_counter() - started:.0f} s so far)", file=sys.stderr, flush=True)
        for c in points:
            k = int(np.searchsorted(cycle, c))
            yield cell, k, {"cell": cell, "cycle": float(cycle[k]), "life": life,
                            "truth": life - float(cycle[k])}


def recalibrations(cells: dict[str, tuple[np.ndarray, np.ndarray]], levels: dict[str, float],
                   draw_set: int = 0, say: bool = False) -> dict[str, Calibration | None]:
    """Each cell's recalibration on the others (leave-one-out), as ``condmon
    forecast`` makes it (:meth:`condmon.store.forecasts.FleetHistory.calibrations`):
    each peer's forecasts take the other peers' whole lives as their prior,
    and so does the cell's."""
    lives = {c: life_of(*_to_end(*cells[c], levels[c])) for c in cells}
    out = {}
    for cell in cells:
        if say:
            print(f"  {cell}: forecasts along the other cells' series for its recalibration ...",
                  file=sys.stderr, flush=True)
        mine = {p: w for p, w in lives.items() if w is not None and p != cell}
        pits: list[tuple[float, float, float, float]] = []
        for c in cells:
            if c != cell:   # the others' lives, as the cell's forecast takes them (or none)
                pits += peer_pits(*cells[c], levels[c], draw_set, tuple(
                    w for p, w in mine.items() if p != c) if len(mine) >= MIN_PEERS else ())
        out[cell] = calibrate(pits, len(cells) - 1, list(mine.values()))
    return out


def draw_set_scores(cells: dict[str, tuple[np.ndarray, np.ndarray]], levels: dict[str, float],
                start: float, every: int, draw_set: int) -> dict[str, dict[str, float]]:
    """condmon's two path rows scored with another set of Monte-Carlo draws."""
    recal = recalibrations(cells, levels, draw_set)
    rows: dict[str, list[dict[str, Any]]] = {m: [] for m in PATH_METHODS}
    for cell, k, common in forecast_points(cells, levels, start, every):
        cycle, capacity = cells[cell]
        rows[PATH_METHODS[0]].append({**common, "forecast": condmon_row(
            cycle, capacity, k, levels[cell], draw_set=draw_set)})
        rows[PATH_METHODS[1]].append({**common, "forecast": condmon_row(
            cycle, capacity, k, levels[cell], recal[cell], draw_set) if recal[cell] else None})
    return {m: score(r) for m, r in rows.items()}


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
    return (float(np.median(left)), float(np.quantile(left, 0.05, method="inverted_cdf")),
            float(np.quantile(left, 0.95, method="inverted_cdf")))


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

    with np.errstate(invalid="ignore"):
        width = np.where(np.isfinite(hi), (hi - lo) / truth, np.inf)
    return {"forecasts": len(done), "missing": len(rows) - len(done),
            "coverage": float(np.mean((lo <= truth) & (truth <= hi))),
            "alpha_lambda_rolling": float(np.mean(within)),
            "alpha_lambda_0.5": at(0.5), "alpha_lambda_0.75": at(0.75),
            "median_relative_width": float(np.median(width)),
            "too_early": float(np.mean(med < truth))}


def matched(rows: list[dict[str, Any]], target: float) -> tuple[float, float]:
    """The factor each interval's ends would be moved by, about its median on
    a log(1 + cycles) scale, for the intervals to hold ``target`` of these
    true remaining lives, and the median relative width they would then have.

    In-sample: read on the forecasts it is scored on, it is not a forecast
    but a measure of sharpness at equal coverage: which method's intervals
    are narrower once both cover the same share. (inf, inf): no factor does.
    """
    done = [r for r in rows if r["forecast"] is not None]
    if not done:
        return math.nan, math.nan
    truth = np.array([r["truth"] for r in done])
    med, lo, hi = (np.log1p(np.array([r["forecast"][i] for r in done])) for i in range(3))
    t = np.log1p(truth)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(t < med, (med - t) / (med - lo), (t - med) / (hi - med))
    need = np.where(t == med, 0.0, np.where(np.isnan(need), np.inf, need))
    factor = float(np.quantile(need, target, method="inverted_cdf"))
    if not np.isfinite(factor):
        return math.inf, math.inf
    bounded = np.isfinite(hi)     # (an unbounded interval stays so, whatever its factor)
    with np.errstate(invalid="ignore", over="ignore"):
        low = np.expm1(med - factor * (med - lo))
        high = np.expm1(med + factor * (hi - med))
    return factor, float(np.median(np.where(bounded, (high - low) / truth, np.inf)))


def draw_spread(spread: dict[str, list[dict[str, float]]], best: float,
                progpy_width: float | None) -> list[dict[str, str]]:
    """Per path row, each figure's median [lowest, highest] over the draw sets,
    and its ratios to the best peer's α-λ and ProgPy's median width."""
    def says(values: list[float]) -> str:
        v = np.asarray(values, dtype=np.float64)
        return f"{np.median(v):.3g} [{v.min():.3g}, {v.max():.3g}]"

    out = []
    for method, sets in spread.items():
        row = {"method": method}
        for key in ("coverage", "alpha_lambda_rolling", "median_relative_width"):
            row[key] = says([s[key] for s in sets])
        row["alpha_lambda / best peer's"] = says([s["alpha_lambda_rolling"] / best for s in sets])
        if progpy_width:
            row["width / ProgPy's"] = says([s["median_relative_width"] / progpy_width
                                            for s in sets])
        out.append(row)
    return out


def _levels(text: list[str]) -> dict[str, float]:
    out = {}
    for item in text:
        cell, _, value = item.partition("=")
        out[cell.strip()] = float(value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--level", type=float, default=None,
                    help="end of life of every cell [Ah] (default: NASA's, per its README)")
    ap.add_argument("--level-for", action="append", default=[], metavar="CELL=LEVEL",
                    help="a cell's own end of life [Ah]")
    ap.add_argument("--every", type=int, default=5, help="cycles between forecasts")
    ap.add_argument("--start", type=float, default=0.3, help="first forecast, fraction of life")
    ap.add_argument("--no-progpy", action="store_true", help="skip the ProgPy peer")
    ap.add_argument("--draw-sets", type=int, default=5,
                    help="Monte-Carlo draw sets condmon's path rows are repeated with, for "
                         "the spread of their figures (1: only the seeds `condmon forecast` uses)")
    args = ap.parse_args()
    if args.draw_sets < 1:
        sys.exit(f"--draw-sets {args.draw_sets}: give 1 or more")
    if not args.data.is_dir():
        sys.exit(f"{args.data}: no such folder (give --data DIR with B0005.csv ...)")
    files = sorted(args.data.glob("*.csv"))
    own = _levels(args.level_for)
    levels = {f.stem: own.get(f.stem, args.level if args.level is not None
                              else EOL.get(f.stem, 1.4)) for f in files}
    cells = {f.stem: read_cell(f) for f in files}
    progpy = None
    if not args.no_progpy:
        try:
            from _progpy_peer import progpy_forecast
            progpy = progpy_forecast
        except ImportError:
            print("ProgPy not installed (pip install '.[bench]'): its measured row is skipped")
    load = os.getloadavg()
    rng = np.random.default_rng(0)
    names = ["condmon", "condmon, recalibrated on the other cells", "condmon, trend method",
             "straight line"] + (["ProgPy 1.9 (measured here)"] if progpy else [])
    rows: dict[str, list[dict[str, Any]]] = {m: [] for m in names}
    started = time.perf_counter()
    recal = recalibrations(cells, levels, say=True)
    timing = {m: 0.0 for m in names}
    for cell, k, common in forecast_points(cells, levels, args.start, args.every, started):
        cycle, capacity = cells[cell]
        level = levels[cell]
        made = {
            "condmon": lambda: condmon_row(cycle, capacity, k, level),
            "condmon, recalibrated on the other cells": lambda: condmon_row(
                cycle, capacity, k, level, recal[cell]) if recal[cell] else None,
            "condmon, trend method": lambda: trend_row(cycle, capacity, k, level),
            "straight line": lambda: line_forecast(cycle, capacity, k, level, rng),
            "ProgPy 1.9 (measured here)": lambda: progpy(cycle, capacity, k, level, seed=k)
            if progpy else None}
        for m in names:
            t0 = time.perf_counter()
            rows[m].append({**common, "forecast": made[m]()})
            timing[m] += time.perf_counter() - t0
    spread: dict[str, list[dict[str, float]]] = {
        m: [score(rows[m])] for m in PATH_METHODS}
    for draw_set in range(1, args.draw_sets):
        print(f"  Monte-Carlo draw set {draw_set + 1} of {args.draw_sets} "
              f"({time.perf_counter() - started:.0f} s so far)", file=sys.stderr, flush=True)
        for m, sc in draw_set_scores(cells, levels, args.start, args.every, draw_set).items():
            spread[m].append(sc)
    elapsed = time.perf_counter() - started
    scores = [{"method": m, **score(r), "seconds": timing[m]} for m, r in rows.items()]
    scores.append({"method": "ProgPy 1.9 (published, 77 forecasts)", "forecasts": 77,
                   "missing": 0, "coverage": PROGPY["coverage"],
                   "alpha_lambda_rolling": PROGPY["alpha_lambda_rolling"],
                   "alpha_lambda_0.5": math.nan, "alpha_lambda_0.75": math.nan,
                   "median_relative_width": math.nan, "too_early": math.nan,
                   "seconds": math.nan})
    keys = ["method", "forecasts", "missing", "coverage", "alpha_lambda_rolling",
            "alpha_lambda_0.5", "alpha_lambda_0.75", "median_relative_width", "too_early",
            "seconds"]
    shown = [{k: s.get(k, math.nan) for k in keys} for s in scores]
    end = os.getloadavg()
    print(table(shown, f"{args.data.name} cells, rolling forecasts every {args.every} cycles "
                       f"from {args.start:.0%} of life (load {load[0]:.2f} at the start, "
                       f"{end[0]:.2f} at the end; {elapsed:.1f} s)"))
    peers = [s for s in scores if s["method"] in ("straight line", "ProgPy 1.9 (measured here)",
                                                   "ProgPy 1.9 (published, 77 forecasts)")]
    best = max(s["alpha_lambda_rolling"] for s in peers)
    measured = [s for s in peers if s["method"] == "ProgPy 1.9 (measured here)"]
    for ours in scores[:3]:
        line = (f"\n{ours['method']}: rolling α-λ / best peer's {ours['alpha_lambda_rolling'] / best:.2f}; "
                f"coverage {ours['coverage']:.2f} (target 0.80-0.97)")
        if measured:
            line += (f"; median width / ProgPy's "
                     f"{ours['median_relative_width'] / measured[0]['median_relative_width']:.2f}")
        print(line, end="")
    print()
    at_cover = []
    for m, r in rows.items():
        row: dict[str, Any] = {"method": m}
        for target in (0.8, 0.9):
            factor, width = matched(r, target)
            row[f"factor for {target:.0%}"] = factor
            row[f"median width at {target:.0%}"] = width
        at_cover.append(row)
    print(table(at_cover, "\nsharpness at equal coverage (in-sample, not a forecast): each "
                          "method's intervals moved about their medians, on log(1 + cycles), "
                          "until they hold 80 % (90 %) of these true lives; the factor and the "
                          "median relative width it gives"))
    ranges = draw_spread(spread, best, measured[0]["median_relative_width"] if measured else None)
    print(table(ranges, f"\ncondmon's path rows over {args.draw_sets} Monte-Carlo draw set(s) "
                        "(median [lowest, highest]); the first set is the table's"))
    path = write_json("prognostics_real", {"load": [load, end], "seconds": elapsed,
                                           "levels": levels, "scores": scores, "forecasts": rows,
                                           "draw_sets": spread, "equal_coverage": at_cover})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
