"""What an isolation found (:func:`condmon.diagnose.isolation.isolate`), with
what it was found from."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.diagnose.residuals import Detection, Normalisation, Residuals
from condmon.diagnose.sensor_faults import SensorFit
from condmon.diagnose.structure import FaultSignature
from condmon.identify.steady_state import SteadyStateEstimate

__all__ = ["IsolationResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class IsolationResult:
    """Everything the isolation found, with what it was found from.

    Attributes
    ----------
    model : str
    detected : bool
    detection_time, onset_time : float or None
        [s]
    fired_residuals : tuple of str
    fsm : FaultSignature
    suspects : tuple of str
    estimates : dict of str to SteadyStateEstimate
    errors : dict of str to float
        RMS of each suspect model's output error after the transient, in units
        of each sensor's noise (about 1 for a model that explains the data). [-]
    isolated : tuple of str
        The least-error suspect and those not significantly worse (ambiguity set).
    statement : str
        The conclusion in words.
    residuals : Residuals
    normalisation : Normalisation
    detection : Detection
    outputs : dict of str to ndarray
        Each suspect model's sensor readings. [sensor units]
    compare_from : float or None
        Start of the comparison window. [s]
    sensor_noise : ndarray
        Per-sample noise of each sensor the errors are expressed in. [sensor units]
    decided : bool
        False when the record could not settle the question: too short to show a
        fault, or a fault detected but not isolable from it.
    reason : str or None
        Why it is not decided (None when it is).
    rejected : dict of str to str
        Suspects left out of the comparison, with the reason (estimate outside
        its plausible range, not converged, simulation failed or timed out).
    notes : tuple of str
        Other things the user should know (pooled normalisation, ...).
    time_limit : float or None
        Wall-time limit of each suspect's model run. [s]
    units : dict of str to str
        Unit of each parameter of the model (of an estimate and its nominal).
    sensor_faults : tuple of SensorFit
        Sensors whose calibration error (a gain or an offset) explains the
        record as well as the best candidate (:mod:`condmon.diagnose.sensor_faults`):
        with none of ``isolated``, no component is named.
    """

    model: str
    detected: bool
    detection_time: float | None
    onset_time: float | None
    fired_residuals: tuple[str, ...]
    fsm: FaultSignature
    suspects: tuple[str, ...]
    estimates: dict[str, SteadyStateEstimate]
    errors: dict[str, float]
    isolated: tuple[str, ...]
    statement: str
    residuals: Residuals
    normalisation: Normalisation
    detection: Detection
    outputs: dict[str, FloatArray]
    compare_from: float | None
    sensor_noise: FloatArray
    decided: bool = True
    reason: str | None = None
    rejected: dict[str, str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    time_limit: float | None = None
    units: dict[str, str] = field(default_factory=dict)
    sensor_faults: tuple[SensorFit, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (keys ``detected``, ``decided``, ``reason``,
        ``detection_time``, ``fired_residuals``, ``fsm``, ``suspects``,
        ``estimates``, ``rejected``, ``errors``, ``isolated``, ...); a number
        that is not finite is ``null``."""
        return {
            "model": self.model,
            "detected": self.detected,
            "decided": self.decided,
            "reason": self.reason,
            # times come from sample grids (k * dt): shown to the nanosecond
            "detection_time": _finite(None if self.detection_time is None
                                      else round(self.detection_time, 9)),
            "onset_time": _finite(None if self.onset_time is None else round(self.onset_time, 9)),
            "fired_residuals": list(self.fired_residuals),
            "fsm": self.fsm.to_dict(),
            "suspects": list(self.suspects),
            "estimates": {p: _finite(e.value) for p, e in self.estimates.items()},
            "units": {p: self.units.get(p, "") for p in self.estimates},
            "estimate_change_percent": {p: _finite(e.change_percent)
                                        for p, e in self.estimates.items()},
            "consistency": {p: _finite(e.consistency) for p, e in self.estimates.items()},
            "rejected": dict(self.rejected),
            "errors": {p: _finite(v) for p, v in self.errors.items()},
            "isolated": list(self.isolated),
            "ambiguous": self.decided and len(self.isolated) + len(self.sensor_faults) > 1,
            "sensor_faults": [f.to_dict() for f in self.sensor_faults],
            "statement": self.statement,
            "notes": list(self.notes),
            "time_limit": _finite(self.time_limit),
            "normalisation": self.normalisation.to_dict(),
        }


def _finite(value: float | None) -> float | None:
    """``value`` as a float, None when missing or not finite (JSON has no NaN)."""
    return None if value is None or not math.isfinite(value) else float(value)
