"""DC-equivalent motor with inertia and viscous friction (SPEC A1).

::

    L di/dt = V - R i - Ke w,      J dw/dt = Kt i - D w,      Ke = gamma Kt

    I/V = (J s + D)/Δ,   w/V = Kt/Δ,   Δ = LJ s² + (LD + RJ) s + (RD + Ke Kt)

Normalised by LJ: ``I/V = (b1 s + b0)/(s² + a1 s + a0)``, ``w/V = c0/(s² + a1 s + a0)``,
and the physical parameters follow exactly once gamma is known.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ModelError
from condmon.models.conversion import tf_d2c_jacobian
from condmon.models.transfer import ContinuousTF, DiscreteTF

__all__ = ["DCMotorParameters", "PARAMETER_NAMES", "PARAMETER_UNITS", "dc_motor_tf",
           "dc_motor_from_tf", "dc_motor_from_discrete"]

FloatArray = NDArray[np.float64]

PARAMETER_NAMES = ("R", "L", "Ke", "Kt", "J", "D")
PARAMETER_UNITS = {"R": "ohm", "L": "H", "Ke": "V s/rad", "Kt": "N m/A",
                   "J": "kg m^2", "D": "N m s/rad"}


@dataclass(frozen=True)
class DCMotorParameters:
    """The six physical parameters of the motor, referred to the motor shaft.

    Attributes
    ----------
    R : float
        Winding resistance. [ohm]
    L : float
        Winding inductance. [H]
    Ke : float
        Back-EMF constant. [V s/rad]
    Kt : float
        Torque constant. [N m/A]
    J : float
        Inertia. [kg m^2]
    D : float
        Viscous friction. [N m s/rad]
    """

    R: float
    L: float
    Ke: float
    Kt: float
    J: float
    D: float

    def as_dict(self) -> dict[str, float]:
        """``{name: value}`` in SI units."""
        return {k: float(v) for k, v in asdict(self).items()}

    def as_array(self) -> FloatArray:
        """Values in the order of :data:`PARAMETER_NAMES`."""
        return np.array([getattr(self, k) for k in PARAMETER_NAMES], dtype=np.float64)


def dc_motor_tf(p: DCMotorParameters) -> ContinuousTF:
    """Continuous model V -> (I, omega) of a parameter set.

    Example
    -------
    >>> g = dc_motor_tf(DCMotorParameters(1.0, 1e-3, 0.05, 0.05, 1e-4, 1e-4))
    >>> g.outputs
    ('I', 'omega')
    """
    LJ = p.L * p.J
    den = np.array([LJ, p.L * p.D + p.R * p.J, p.R * p.D + p.Ke * p.Kt]) / LJ
    nums = np.array([[0.0, p.J, p.D], [0.0, 0.0, p.Kt]]) / LJ
    return ContinuousTF(den, nums, ("I", "omega"), "V")


def _coefficients_to_physical(a1: float, a0: float, b1: float, b0: float, c0: float,
                              gamma: float) -> FloatArray:
    if b1 == 0.0 or c0 == 0.0:
        raise ModelError("degenerate model: the current numerator's s-coefficient or "
                         "the speed numerator is zero, no physical parameters follow")
    L = 1.0 / b1
    R = L * (a1 - b0 / b1)
    Kt = (a0 - R * b0) / (gamma * c0)
    Ke = gamma * Kt
    J = Kt / (L * c0)
    D = b0 * L * J
    return np.array([R, L, Ke, Kt, J, D])


def dc_motor_from_tf(g: ContinuousTF, gamma: float) -> DCMotorParameters:
    """Physical parameters of a continuous model (outputs ``I`` then ``omega``).

    Parameters
    ----------
    g : ContinuousTF
        Second-order model with outputs ``("I", "omega")``.
    gamma : float
        Ke / Kt, a known constant of the motor. [-]

    Returns
    -------
    DCMotorParameters

    Example
    -------
    >>> p = DCMotorParameters(1.0, 1.2e-3, 0.0475, 0.05, 5e-5, 1e-4)
    >>> q = dc_motor_from_tf(dc_motor_tf(p), 0.95)
    >>> bool(np.allclose(q.as_array(), p.as_array()))
    True
    """
    if g.order != 2 or len(g.outputs) != 2:
        raise ModelError(f"the DC-motor model needs a 2nd-order model with two outputs, "
                         f"got order {g.order} with outputs {g.outputs}")
    if not gamma > 0:
        raise ModelError(f"gamma must be positive, got {gamma}")
    _, a1, a0 = g.den
    _, b1, b0 = g.nums[0]
    c0 = g.nums[1, 2]
    return DCMotorParameters(*map(float, _coefficients_to_physical(a1, a0, b1, b0, c0,
                                                                   gamma)))


def dc_motor_from_discrete(model: DiscreteTF, covariance: FloatArray, gamma: float
                           ) -> tuple[DCMotorParameters, FloatArray]:
    """Physical parameters of a discrete estimate and their covariance.

    The covariance is propagated by the delta method, ``J Σ Jᵀ``, with the
    Jacobian of the whole map: the ZOH inverse's in closed form
    (:func:`~condmon.models.conversion.tf_d2c_jacobian`), then that of the
    algebraic map to the parameters by central differences.

    Parameters
    ----------
    model : DiscreteTF
        Second-order estimate, outputs ``("I", "omega")``, numerators with one
        sample of delay.
    covariance : ndarray, shape (6, 6)
        Covariance of ``[a1, a2, bI1, bI2, bw1, bw2]``.
    gamma : float
        Ke / Kt. [-]

    Returns
    -------
    params : DCMotorParameters
    covariance : ndarray, shape (6, 6)
        Covariance of ``(R, L, Ke, Kt, J, D)`` in SI units.
    """
    if model.order != 2 or model.outputs != ("I", "omega"):
        raise ModelError(f"the DC-motor model needs outputs ('I', 'omega') of order 2, "
                         f"got {model.outputs} of order {model.order}")
    cont, J_cont = tf_d2c_jacobian(model)   # rows: a1, a0, bI1, bI0, bw1, bw0 (continuous)
    used = [0, 1, 2, 3, 5]                   # bw1 is structurally zero
    c = np.r_[cont.den[1:], cont.nums[0, 1:], cont.nums[1, 2]]

    def physical(v: FloatArray) -> FloatArray:
        a1, a0, b1, b0, c0 = map(float, v)
        return _coefficients_to_physical(a1, a0, b1, b0, c0, gamma)

    values = physical(c)
    dphys = np.empty((6, c.size))
    for k in range(c.size):   # (a few divisions: central differences cost nothing)
        h = 1e-6 * max(abs(c[k]), 1e-12)
        up, down = c.copy(), c.copy()
        up[k] += h
        down[k] -= h
        dphys[:, k] = (physical(up) - physical(down)) / (2 * h)
    jac = dphys @ J_cont[used]
    cov = jac @ covariance @ jac.T
    return DCMotorParameters(*map(float, values)), cov
