"""A sensor's calibration error as a candidate beside the component faults.

The isolation compares one model per suspect parameter with the record. A
sensor that reads wrong (a speed pickup 10 % high, a pressure gauge whose
zero drifted) changes the residuals too, and the component whose model bends
the readings most alike would be named for it: a model-based isolation cannot
tell a sensor from a parameter without a model of the sensor's fault. So each
sensor gets two such models here, beside the nominal plant's run:

- **gain**: the sensor reads ``(1 + g)`` times the true value;
- **offset**: it reads the true value plus ``b``.

Each is fitted to the comparison window in closed form (least squares of the
one sensor's readings on the nominal model's) and scored as the suspects
are: the RMS output error over every sensor, in each sensor's noise. The
isolation (:func:`condmon.diagnose.isolation.isolate`) then holds them to the
same F test as the component suspects. Why by hand: each fit is one ratio of
sums; no library offers the candidate set.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

__all__ = ["SensorFit", "sensor_fits", "f_limit", "alike", "sensor_statement",
           "own_sensor_faults"]

if TYPE_CHECKING:
    from condmon.models.declared import PlantModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SensorFit:
    """One sensor's calibration error fitted to the record.

    Attributes
    ----------
    sensor : str
        The sensor's name in the declaration.
    kind : {"gain", "offset"}
        A reading ``(1 + value)`` times the true one, or the true one plus ``value``.
    value : float
        The fitted error: a fraction for a gain [-], the sensor's unit for an
        offset [sensor unit].
    error : float
        RMS output error of the nominal model with this sensor's error, over
        every sensor, in units of each sensor's noise (about 1 when it
        explains the record). [-]
    unit : str
        The unit of ``value``: "-" for a gain, the sensor's for an offset.
    """

    sensor: str
    kind: Literal["gain", "offset"]
    value: float
    error: float
    unit: str = "-"

    @property
    def name(self) -> str:
        """``"<sensor> sensor <kind>"``: how a statement names the candidate."""
        return f"{self.sensor} sensor {self.kind}"

    def describe(self) -> str:
        """The sensor's error in words.

        Example
        -------
        >>> SensorFit("omega_m", "gain", 0.1, 1.04).describe()
        'the omega_m sensor reading 10.0 % high'
        >>> SensorFit("Ps", "offset", -2.5e4, 1.1, "Pa").describe()
        'the Ps sensor reading 2.5e+04 Pa low'
        """
        way = "high" if self.value > 0 else "low"
        unit = f" {self.unit}" if self.unit not in ("", "-") else ""
        size = (f"{100 * abs(self.value):.1f} %" if self.kind == "gain"
                else f"{abs(self.value):.3g}{unit}")
        return f"the {self.sensor} sensor reading {size} {way}"

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: sensor, kind, value, unit, error."""
        return {"sensor": self.sensor, "kind": self.kind, "value": float(self.value),
                "unit": self.unit, "error": float(self.error)}


def f_limit(n: int, alpha: float) -> float:
    """The ``1 − alpha`` quantile of F(n, n): the largest ratio of two mean
    squared errors of white noise over ``n`` samples each that is not
    significant at ``alpha``. [-]

    Example
    -------
    >>> round(f_limit(5000, 0.01), 3)
    1.068
    """
    from scipy.special import fdtri  # the F quantile, without scipy.stats' import (~0.5 s)

    return float(fdtri(n, n, 1.0 - alpha))


def sensor_fits(y: FloatArray, nominal: FloatArray, noise: FloatArray, mask: NDArray[np.bool_],
                sensors: Sequence[str], units: Sequence[str] = ()) -> tuple[SensorFit, ...]:
    """Each sensor's gain and offset error fitted to the record (see the module).

    Parameters
    ----------
    y : ndarray, shape (n, n_sensors)
        The record's sensor readings. [sensor units]
    nominal : ndarray, shape (n, n_sensors)
        The nominal model's readings beside it. [sensor units]
    noise : ndarray, shape (n_sensors,)
        Each sensor's per-sample noise. [sensor units]
    mask : ndarray of bool, shape (n,)
        The comparison window.
    sensors : sequence of str
        The sensors' names, in column order.
    units : sequence of str, optional
        Their units (an offset's), in the same order.

    Returns
    -------
    tuple of SensorFit
        Two per sensor (gain, offset); none for a sensor the nominal model
        holds at zero over the window (a gain cannot be fitted to it).

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> t = np.linspace(0.0, 10.0, 1001)
    >>> nominal = np.column_stack([np.sin(t) + 2.0, np.cos(t)])
    >>> y = nominal * [1.1, 1.0] + 0.01 * rng.standard_normal((1001, 2))
    >>> fits = sensor_fits(y, nominal, np.array([0.01, 0.01]), t >= 0, ["a", "b"])
    >>> best = min(fits, key=lambda f: f.error)
    >>> best.name, round(best.value, 3), round(best.error, 1)
    ('a sensor gain', 0.1, 1.0)
    """
    ya, pa = y[mask], nominal[mask]
    if ya.shape[0] == 0:
        return ()
    scaled = (ya - pa) / noise
    out = []
    for j, sensor in enumerate(sensors):
        rest = float(np.sum(scaled ** 2) - np.sum(scaled[:, j] ** 2))
        size = ya.size
        power = float(pa[:, j] @ pa[:, j])
        if power > 0 and math.isfinite(power):
            gain = float(ya[:, j] @ pa[:, j]) / power
            # the gain scales the reading's noise with it
            e = (ya[:, j] - gain * pa[:, j]) / (noise[j] * (abs(gain) or 1.0))
            out.append(SensorFit(sensor, "gain", gain - 1.0,
                                 math.sqrt((rest + float(e @ e)) / size)))
        offset = float(np.mean(ya[:, j] - pa[:, j]))
        e = (ya[:, j] - pa[:, j] - offset) / noise[j]
        out.append(SensorFit(sensor, "offset", offset, math.sqrt((rest + float(e @ e)) / size),
                             units[j] if j < len(units) else ""))
    return tuple(out)


def alike(fits: Sequence[SensorFit], errors: Mapping[str, float], n: int, alpha: float,
          explain_limit: float) -> tuple[tuple[SensorFit, ...], tuple[str, ...]]:
    """The sensor errors, and the components, whose models explain the record
    as well as the best of all of them (the F test at ``alpha`` over ``n``
    samples, as the component suspects are held to each other); nothing when
    no sensor error is among them, or none leaves less than
    ``explain_limit`` noise standard deviations. Both are ordered best first.

    Example
    -------
    >>> fits = [SensorFit("w", "gain", 0.1, 1.02), SensorFit("w", "offset", 1.3, 2.6)]
    >>> sensors, components = alike(fits, {"Dp": 9.3, "Dm": 13.4}, 9808, 0.01, 10.0)
    >>> [f.name for f in sensors], components
    (['w sensor gain'], ())
    >>> alike(fits, {"Dp": 1.0}, 9808, 0.01, 10.0)[1]
    ('Dp',)
    """
    usable = {p: e for p, e in errors.items() if math.isfinite(e)}
    if not fits or not min(f.error for f in fits) <= explain_limit:
        return (), ()
    floor = max(min([*(f.error for f in fits), *usable.values()]), 1e-300)
    limit = f_limit(n, alpha)
    sensors = tuple(sorted((f for f in fits if (f.error / floor) ** 2 <= limit),
                           key=lambda f: f.error))
    if not sensors:
        return (), ()
    components = tuple(sorted((p for p, e in usable.items() if (e / floor) ** 2 <= limit),
                              key=lambda p: usable[p]))
    return sensors, components


def sensor_statement(sensors: Sequence[SensorFit], components: Sequence[str],
                     errors: Mapping[str, float], n: int, alpha: float
                     ) -> tuple[str, str | None]:
    """The conclusion in words when sensor errors are among the best
    explanations (:func:`alike`), and why nothing is isolated (None when the
    best explains the record to the sensors' noise: the F test at ``alpha``
    over ``n`` samples, against noise alone).

    Example
    -------
    >>> s = [SensorFit("w", "gain", 0.1, 1.02)]
    >>> sensor_statement(s, (), {"Dp": 9.3}, 9808, 0.01)[0]
    "no component fault: the w sensor reading 10.0 % high explains the record (error 1.02 noise sd); every component's model is significantly worse (the best, Dp, leaves 9.3; F test at 0.01)"
    >>> sensor_statement(s, ("Dp",), {"Dp": 1.03}, 9808, 0.01)[0]
    'ambiguous: Dp, or the w sensor reading 10.0 % high, explain the data equally well'
    >>> sensor_statement([SensorFit("w", "gain", 0.29, 6.5)], (), {"Rv": 8.6}, 9808, 0.01)[1]
    "no candidate explains the record: the best, the w sensor reading 29.0 % high (6.5), leaves more error [noise sd] than the 1.02 noise alone reaches (F test at 0.01): the fault may be none of the candidates, several, or a sensor's"
    """
    said = " or ".join(f.describe() for f in sensors)
    best = min([sensors[0].error, *(errors[p] for p in components)])
    limit = f_limit(n, alpha)
    if best ** 2 > limit:   # not explained: neither a component nor a sensor is named
        each = [f"{p} ({errors[p]:.3g})" for p in components] + [
            f"{f.describe()} ({f.error:.3g})" for f in sensors]
        return "", (f"no candidate explains the record: the best, {', '.join(each)}, "
                    f"leave{'s' if len(each) == 1 else ''} "
                    f"more error [noise sd] than the {math.sqrt(limit):.3g} noise alone "
                    f"reaches (F test at {alpha:g}): the fault may be none of the candidates, "
                    "several, or a sensor's")
    if components:
        return (f"ambiguous: {', '.join(components)}, or {said}, explain the data equally "
                "well"), None
    text = (f"no component fault: {said} explains the record (error {sensors[0].error:.3g} "
            "noise sd)")
    finite = {p: e for p, e in errors.items() if math.isfinite(e)}
    if finite:
        p = min(finite, key=lambda k: finite[k])
        text += (f"; every component's model is significantly worse (the best, {p}, leaves "
                 f"{finite[p]:.3g}; F test at {alpha:g})")
    return text, None


def own_sensor_faults(model: PlantModel) -> frozenset[tuple[str, str]]:
    """The ``(sensor, kind)`` errors the declaration models itself: a sensor
    whose reading names a fault-candidate parameter added to it (``measures
    = "Ps + bPs"``) has its offset modelled, one multiplied (``"omega_m *
    kw"``) its gain, and one written otherwise both. These get no candidate
    of their own, so the two never compete.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> sorted(own_sensor_faults(load_plant_model("hst")))
    []
    """
    faults = set(model.fault_candidates)
    out = set()
    for s in model.sensors:
        text = s.measures.replace(" ", "")
        for p in faults & set(re.findall(r"[A-Za-z_]\w*", text)):
            beside = "".join(re.findall(rf"(.?)(?<![\w.]){re.escape(p)}(?![\w.])(.?)", text)[0])
            if beside and set(beside) <= set("+-"):
                out.add((s.name, "offset"))
            elif beside and set(beside) <= set("*/") and "+" not in text and "-" not in text:
                out.add((s.name, "gain"))
            else:
                out.update({(s.name, "offset"), (s.name, "gain")})
    return frozenset(out)
