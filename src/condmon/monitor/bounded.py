"""The minimum of a function of one variable on an interval, without scipy.

A forecast fits its exponential's rate on a bracket; importing
``scipy.optimize`` for that costs a check about 0.3 s. :func:`bounded_minimum`
is Brent's method as ``scipy.optimize.minimize_scalar(method="bounded")``
runs it (its ``_minimize_scalar_bounded``, BSD-licensed, the same steps in the
same order), so the rate found is scipy's to the bit (checked in the tests).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["bounded_minimum"]


def bounded_minimum(func: Callable[[float], float], lower: float, upper: float,
                    xatol: float = 1e-5, maxiter: int = 500) -> float:
    """Where ``func`` is smallest on ``[lower, upper]`` (Brent's method:
    golden-section and parabolic steps).

    Parameters
    ----------
    func : callable
        The function of one variable.
    lower, upper : float
        The finite bounds, ``lower <= upper``. [same unit as x]
    xatol : float
        Absolute tolerance on the minimiser. [same unit as x]
    maxiter : int
        Most evaluations of ``func``.

    Returns
    -------
    float
        The minimiser found.

    Example
    -------
    >>> round(bounded_minimum(lambda x: (x - 0.3) ** 2, 0.0, 1.0), 4)
    0.3
    """
    if not (math.isfinite(lower) and math.isfinite(upper)) or lower > upper:
        raise ValueError(f"bounds must be finite and ordered, got ({lower}, {upper})")
    sqrt_eps = math.sqrt(2.2e-16)
    golden_mean = 0.5 * (3.0 - math.sqrt(5.0))
    a, b = lower, upper
    fulc = a + golden_mean * (b - a)
    nfc, xf = fulc, fulc
    rat = e = 0.0
    x = xf
    fx = func(x)
    num = 1
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = sqrt_eps * np.abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while np.abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = True
        if np.abs(e) > tol1:  # a parabolic step, if acceptable
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = np.abs(q)
            r = e
            e = rat
            if (np.abs(p) < np.abs(0.5 * q * r)) and (p > q * (a - xf)) and (p < q * (b - xf)):
                rat = (p + 0.0) / q
                x = xf + rat
                if ((x - a) < tol2) or ((b - x) < tol2):
                    rat = tol1 * (np.sign(xm - xf) + ((xm - xf) == 0))
            else:
                golden = True
        if golden:
            e = a - xf if xf >= xm else b - xf
            rat = golden_mean * e
        x = xf + (np.sign(rat) + (rat == 0)) * np.maximum(np.abs(rat), tol1)
        fu = func(x)
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if (fu <= fnfc) or (nfc == xf):
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif (fu <= ffulc) or (fulc == xf) or (fulc == nfc):
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = sqrt_eps * np.abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxiter:
            break
    return float(xf)
