"""The built-in demonstration: a healthy and a faulty simulated test, estimated.

Everything ``condmon demo`` prints comes from :func:`run_demo`, callable from Python.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from condmon.identify.estimate import EstimateResult, estimate
from condmon.simulate.actuator import load_actuator_rig, simulate_actuator

__all__ = ["DemoResult", "run_demo"]


@dataclass(frozen=True, eq=False)
class DemoResult:
    """Outcome of the demonstration.

    Attributes
    ----------
    healthy, faulty : EstimateResult
        Estimates from the healthy and the faulty test.
    truth_healthy, truth_faulty : dict of str to float
        True parameters of each test (SI units).
    faults : tuple of str
        Faults applied to the second test.
    """

    healthy: EstimateResult
    faulty: EstimateResult
    truth_healthy: dict[str, float]
    truth_faulty: dict[str, float]
    faults: tuple[str, ...]

    def table(self) -> pd.DataFrame:
        """Per parameter: true and estimated values, estimated and true % change."""
        rows = {}
        for k, est_h in self.healthy.parameters.items():
            est_f = self.faulty.parameters[k]
            th, tf = self.truth_healthy[k], self.truth_faulty[k]
            rows[k] = {
                "unit": self.healthy.units[k],
                "true_healthy": th,
                "estimated_healthy": est_h,
                "std_error_healthy": self.healthy.std_errors[k],
                "true_faulty": tf,
                "estimated_faulty": est_f,
                "change_estimated_percent": 100.0 * (est_f - est_h) / est_h,
                "change_true_percent": 100.0 * (tf - th) / th,
            }
        return pd.DataFrame.from_dict(rows, orient="index")


def run_demo(faults: Sequence[str] = ("R=+40%",), seed: int = 0) -> DemoResult:
    """Simulate a healthy and a faulty built-in test and estimate both.

    Parameters
    ----------
    faults : sequence of str
        Faults of the second test (e.g. ``"R=+40%"``, ``"D=*7"``).
    seed : int
        Seed of the first test; the second uses ``seed + 1``.

    Returns
    -------
    DemoResult

    Example
    -------
    >>> res = run_demo(seed=3)
    >>> bool(30 < res.table().loc["R", "change_estimated_percent"] < 50)
    True
    """
    healthy_rig = load_actuator_rig()
    faulty_rig = healthy_rig.with_faults(faults)
    healthy = estimate(simulate_actuator(healthy_rig, seed=seed), source="healthy test")
    faulty = estimate(simulate_actuator(faulty_rig, seed=seed + 1), source="faulty test")
    return DemoResult(healthy, faulty, healthy_rig.physical(), faulty_rig.physical(),
                      tuple(faults))
