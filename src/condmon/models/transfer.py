"""Transfer-function models with a common denominator (single input, several outputs).

The identification stage produces a :class:`DiscreteTF`; the zero-order-hold inverse
turns it into a :class:`ContinuousTF`, from which physical parameters are read.
Both are immutable, carry their sample time explicitly and convert to
python-control objects for users who work there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon._filter import lfilter
from condmon.errors import ModelError

__all__ = ["DiscreteTF", "ContinuousTF"]

FloatArray = NDArray[np.float64]


def _names(outputs: tuple[str, ...], nums: FloatArray) -> tuple[str, ...]:
    return tuple(outputs) if outputs else tuple(f"y{j}" for j in range(nums.shape[0]))


def _check_shapes(den: FloatArray, nums: FloatArray, outputs: tuple[str, ...]) -> None:
    if den.ndim != 1 or den.size < 2:
        raise ModelError(f"denominator must be a 1-D array of length >= 2, got shape {den.shape}")
    if den[0] == 0.0:
        raise ModelError("denominator leading coefficient is zero")
    if nums.ndim != 2 or nums.shape[1] != den.size:
        raise ModelError(
            f"numerators must have shape (n_outputs, {den.size}), got {nums.shape}"
        )
    if len(outputs) != nums.shape[0]:
        raise ModelError(
            f"{len(outputs)} output names given for {nums.shape[0]} numerators"
        )
    if not (np.all(np.isfinite(den)) and np.all(np.isfinite(nums))):
        raise ModelError("transfer-function coefficients contain NaN or inf")


def _freeze(obj: Any) -> None:
    """Validate, normalise to a monic denominator and freeze a TF's arrays."""
    den = np.asarray(obj.den, dtype=np.float64).copy()
    nums = np.atleast_2d(np.asarray(obj.nums, dtype=np.float64)).copy()
    outputs = _names(obj.outputs, nums)
    _check_shapes(den, nums, outputs)
    nums /= den[0]
    den /= den[0]
    den.flags.writeable = False
    nums.flags.writeable = False
    object.__setattr__(obj, "den", den)
    object.__setattr__(obj, "nums", nums)
    object.__setattr__(obj, "outputs", outputs)


def _describe(obj: Any, **head: Any) -> dict[str, Any]:
    return {**head, "input": obj.input, "den": obj.den.tolist(),
            "nums": {name: row.tolist() for name, row in zip(obj.outputs, obj.nums)}}


def _control_tf(obj: Any, *dt: float) -> Any:
    import control

    # Numerators and denominator have equal length n+1; in discrete time multiplying
    # both by z^n turns q^-1 coefficient arrays into z arrays unchanged.
    num = [[list(row)] for row in obj.nums]
    den = [[list(obj.den)] for _ in obj.nums]
    return control.tf(num, den, *dt, inputs=[obj.input], outputs=list(obj.outputs))


@dataclass(frozen=True, eq=False)
class DiscreteTF:
    """Discrete single-input multi-output transfer function, common denominator.

    ``y_j(k) = B_j(q^-1) / A(q^-1) u(k)`` with

    ``A = den[0] + den[1] q^-1 + ... + den[n] q^-n`` (``den[0] == 1``) and
    ``B_j = nums[j, 0] + nums[j, 1] q^-1 + ... + nums[j, n] q^-n``.

    Attributes
    ----------
    den : ndarray, shape (n+1,)
        Denominator coefficients in ascending powers of q^-1. [-]
    nums : ndarray, shape (n_outputs, n+1)
        Numerator coefficients in ascending powers of q^-1. [output unit / input unit]
    dt : float
        Sample time. [s]
    outputs : tuple of str
        Output names, one per numerator row (default ``y0, y1, ...``).
    input : str
        Input name.

    Example
    -------
    >>> g = DiscreteTF(np.array([1.0, -0.5]), np.array([[0.0, 1.0]]), 1e-3)
    >>> g.poles()
    array([0.5+0.j])
    """

    den: FloatArray
    nums: FloatArray
    dt: float
    outputs: tuple[str, ...] = ()
    input: str = "u"

    def __post_init__(self) -> None:
        if not self.dt > 0:
            raise ModelError(f"sample time must be positive, got {self.dt}")
        _freeze(self)

    @property
    def order(self) -> int:
        """Number of poles."""
        return int(self.den.size - 1)

    def poles(self) -> NDArray[np.complex128]:
        """Poles in the z-plane."""
        return np.roots(self.den).astype(np.complex128)

    def simulate(self, u: FloatArray) -> FloatArray:
        """Noise-free output for input ``u`` from rest, shape (len(u), n_outputs)."""
        u = np.asarray(u, dtype=np.float64)
        x = lfilter([1.0], self.den, u)
        out = np.empty((u.size, len(self.nums)), order="F")
        for j, b in enumerate(self.nums):   # each numerator: the first N of one convolution
            out[:, j] = np.convolve(x, b)[: u.size]
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        return _describe(self, domain="discrete", variable="q^-1", dt=self.dt)

    def to_control(self) -> Any:
        """python-control ``TransferFunction`` (outputs x 1), sample time ``dt``."""
        return _control_tf(self, self.dt)


@dataclass(frozen=True, eq=False)
class ContinuousTF:
    """Continuous single-input multi-output transfer function, common denominator.

    ``y_j(s) = (nums[j, 0] s^n + ... + nums[j, n]) / (s^n + den[1] s^(n-1) + ... + den[n])``

    Attributes
    ----------
    den : ndarray, shape (n+1,)
        Denominator coefficients in descending powers of s, monic. [s^-k]
    nums : ndarray, shape (n_outputs, n+1)
        Numerator coefficients in descending powers of s.
    outputs : tuple of str
        Output names (default ``y0, y1, ...``).
    input : str
        Input name.

    Example
    -------
    >>> g = ContinuousTF(np.array([1.0, 3.0, 2.0]), np.array([[0.0, 0.0, 2.0]]))
    >>> np.sort(g.poles().real)
    array([-2., -1.])
    """

    den: FloatArray
    nums: FloatArray
    outputs: tuple[str, ...] = ()
    input: str = "u"

    def __post_init__(self) -> None:
        _freeze(self)

    @property
    def order(self) -> int:
        """Number of poles."""
        return int(self.den.size - 1)

    def poles(self) -> NDArray[np.complex128]:
        """Poles in the s-plane. [rad/s]"""
        return np.roots(self.den).astype(np.complex128)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        return _describe(self, domain="continuous", variable="s")

    def to_control(self) -> Any:
        """python-control ``TransferFunction`` (outputs x 1)."""
        return _control_tf(self)
