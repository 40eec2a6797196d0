"""NASA ProgPy as a peer on NASA's Li-ion cells: Kalman filter, then Monte Carlo.

    python benchmarks/_progpy_peer.py

Needs ``pip install progpy==1.9.0``. The same rolling forecasts as
``bench_prognostics_real.py`` (from 30 % of each cell's life, every 5th cycle,
each from the cycles up to it only), by ProgPy alone, and their score.

The model (:class:`CapacityFade`) is a linear fade with a random-walk rate, one
step per cycle::

    capacity[t+1] = capacity[t] + rate[t] + w_c     w_c ~ N(0, q_c²)
    rate[t+1]     = rate[t] + w_r                   w_r ~ N(0, q_r²)
    measured[t]   = capacity[t] + v                 v   ~ N(0, σ_m²)

with the event ``EOL`` when the capacity state is below the end-of-life level.

The noises come from the cycles seen so far, by one fixed rule (no constant
here was chosen by looking at the scores): with ``s`` the standard deviation
of the first differences of the measured capacity (cycles 0..k) and ``n`` the
number of those differences,

- measurement noise σ_m = s / √2 (the difference of two independent
  measurements has twice a measurement's variance);
- process noise on the rate q_r = s / n, so that the rate's random walk over
  the cycles seen (q_r·√n) is as large as the standard error of their mean
  rate (s / √n): the rate may drift by about what the history can resolve;
- process noise on the capacity q_c = q_r / √3, the capacity variance a
  rate random walk adds within one cycle (q_r²·dt³/3, dt = 1).

The Kalman filter starts at cycle 0 from capacity = the first measurement
(variance σ_m²) and rate = 0 (variance s²), with Q = diag(q_c², q_r²) and
R = σ_m²; Monte Carlo uses the same noises as the model's process noise.
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from progpy import LinearModel
from progpy.predictors import MonteCarlo
from progpy.state_estimators import KalmanFilter
from progpy.uncertain_data import MultivariateNormalDist

sys.path.insert(0, str(Path(__file__).parent))
from bench_prognostics_real import DATA, EOL, end_of_life, read_cell, score  # noqa: E402,F401

N_SAMPLES = 1000   # Monte Carlo samples per forecast
HORIZON = 4.0      # prediction horizon, in multiples of the cycles seen so far


class CapacityFade(LinearModel):
    """Capacity [Ah] fading at a random-walk rate [Ah per cycle]; ``EOL`` below ``level``.

    Parameters: ``level`` (end of life [Ah]) and ``c0`` (the capacity at which the
    event state is 1), besides ProgPy's ``process_noise`` and ``measurement_noise``
    (standard deviations per step and per measurement).
    """

    inputs: list[str] = []
    states = ["capacity", "rate"]
    outputs = ["capacity"]
    events = ["EOL"]

    A = np.array([[0.0, 1.0], [0.0, 0.0]])   # d capacity / d cycle = rate
    C = np.array([[1.0, 0.0]])                # the capacity is measured
    F = None                                  # event state and threshold below

    default_parameters = {"level": 1.4, "c0": 2.0,
                          "process_noise": {"capacity": 0.0, "rate": 0.0},
                          "measurement_noise": {"capacity": 0.0}}

    def event_state(self, x: Any) -> dict[str, float]:
        level, c0 = self.parameters["level"], self.parameters["c0"]
        span = max(c0 - level, 1e-9)
        return {"EOL": float(np.clip((x["capacity"] - level) / span, 0.0, 1.0))}

    def threshold_met(self, x: Any) -> dict[str, bool]:
        return {"EOL": bool(x["capacity"] < self.parameters["level"])}


def noises(capacity: np.ndarray) -> tuple[float, float, float, float]:
    """``s``, σ_m, q_c and q_r from the measured capacities (module docstring). [Ah...]"""
    d = np.diff(capacity)
    s = float(np.std(d, ddof=1))
    q_r = s / d.size
    return s, s / math.sqrt(2.0), q_r / math.sqrt(3.0), q_r


def progpy_forecast(cycle: np.ndarray, capacity: np.ndarray, k: int, level: float,
                    seed: int = 0) -> tuple[float, float, float] | None:
    """ProgPy's remaining cycles (median, 5 %, 95 %) from the cycles up to index ``k``.

    Kalman filter over cycles 0..k, then Monte Carlo from cycle[k] to the event;
    samples that do not reach it within the horizon count as infinite.
    """
    if k < 3:
        return None
    y = capacity[:k + 1]
    s, sigma_m, q_c, q_r = noises(y)
    model = CapacityFade(level=level, c0=float(y[0]),
                         process_noise={"capacity": q_c, "rate": q_r},
                         measurement_noise={"capacity": sigma_m})
    x0 = MultivariateNormalDist(model.states, [float(y[0]), 0.0],
                                np.diag([sigma_m ** 2, s ** 2]))
    kf = KalmanFilter(model, x0, t0=float(cycle[0]), dt=1.0,
                      Q=np.diag([q_c ** 2, q_r ** 2]), R=np.array([[sigma_m ** 2]]))
    for t, z in zip(cycle[1:k + 1], y[1:]):
        kf.estimate(float(t), {}, {"capacity": float(z)})

    horizon = HORIZON * float(cycle[k])
    np.random.seed(seed)
    with warnings.catch_warnings():
        # ProgPy's own internals use its deprecated SimResult.pop
        warnings.simplefilter("ignore", DeprecationWarning)
        result = MonteCarlo(model).predict(
            kf.x, n_samples=N_SAMPLES, dt=1.0, t0=float(cycle[k]), horizon=horizon,
            save_freq=horizon, events=["EOL"])
    toe = np.array([math.inf if e["EOL"] is None else e["EOL"]
                    for e in result.time_of_event], dtype=np.float64)
    left = np.maximum(toe - float(cycle[k]), 0.0)
    # quantiles by sorting ("inverted_cdf"), so that infinite samples stay infinite
    med, lo, hi = np.quantile(left, [0.5, 0.05, 0.95], method="inverted_cdf")
    return float(med), float(lo), float(hi)


def main() -> None:
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    for cell, level in EOL.items():
        cycle, capacity = read_cell(DATA / f"{cell}.csv")
        life = end_of_life(cycle, capacity, level)
        for c in np.arange(math.ceil(0.3 * life), life, 5):
            k = int(np.searchsorted(cycle, c))
            rows.append({"cell": cell, "cycle": float(cycle[k]), "life": life,
                         "truth": life - float(cycle[k]),
                         "forecast": progpy_forecast(cycle, capacity, k, level, seed=k)})
    elapsed = time.perf_counter() - started
    print(f"NASA ProgPy (KalmanFilter + MonteCarlo, {N_SAMPLES} samples), "
          f"{len(rows)} rolling forecasts, {elapsed:.1f} s")
    print(score(rows))


if __name__ == "__main__":
    main()
