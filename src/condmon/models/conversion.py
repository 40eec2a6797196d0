"""Zero-order-hold conversions between continuous and discrete time.

:func:`d2c` is the exact inverse of ZOH discretisation. It is written here because
neither scipy nor python-control offers it for state-space models with a correct
input matrix: the inverse must take the matrix logarithm of the *augmented* matrix
``[[Ad, Bd], [0, I]]`` (whose exponential produced ``Ad`` and ``Bd`` together), not of
``Ad`` alone followed by a guess for ``B``.

References
----------
.. [1] G. F. Franklin, J. D. Powell, M. Workman, *Digital Control of Dynamic Systems*,
   3rd ed., 1998, sec. 4.3.3 (ZOH equivalent via the augmented exponential).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConversionError, ModelError
from condmon.models.transfer import ContinuousTF, DiscreteTF

__all__ = ["StateSpace", "c2d", "d2c", "tf_c2d", "tf_d2c", "tf_d2c_jacobian",
           "d2c_coefficients"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class StateSpace:
    """State-space model ``x' = A x + B u``, ``y = C x + D u`` (``dt`` = 0: continuous).

    Attributes
    ----------
    A, B, C, D : ndarray
        System matrices, shapes (n, n), (n, m), (p, n), (p, m).
    dt : float
        Sample time [s]; 0 for continuous time.
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    D: FloatArray
    dt: float = 0.0

    def __post_init__(self) -> None:
        A = np.atleast_2d(np.asarray(self.A, dtype=np.float64))
        B = np.atleast_2d(np.asarray(self.B, dtype=np.float64))
        C = np.atleast_2d(np.asarray(self.C, dtype=np.float64))
        D = np.atleast_2d(np.asarray(self.D, dtype=np.float64))
        n = A.shape[0]
        if A.shape != (n, n):
            raise ModelError(f"A must be square, got shape {A.shape}")
        if B.shape[0] != n or C.shape[1] != n or D.shape != (C.shape[0], B.shape[1]):
            raise ModelError(
                f"inconsistent shapes A{A.shape} B{B.shape} C{C.shape} D{D.shape}"
            )
        for name, value in (("A", A), ("B", B), ("C", C), ("D", D)):
            object.__setattr__(self, name, value)


def c2d(sys: StateSpace, dt: float) -> StateSpace:
    """Zero-order-hold discretisation of a continuous state-space model.

    Parameters
    ----------
    sys : StateSpace
        Continuous model (``sys.dt == 0``).
    dt : float
        Sample time. [s]

    Returns
    -------
    StateSpace
        Discrete model with sample time ``dt``.

    Example
    -------
    >>> s = StateSpace([[-1.0]], [[1.0]], [[1.0]], [[0.0]])
    >>> round(float(c2d(s, 0.1).A[0, 0]), 6)
    0.904837
    """
    if sys.dt != 0.0:
        raise ModelError("c2d expects a continuous model (dt == 0)")
    if not dt > 0:
        raise ModelError(f"sample time must be positive, got {dt}")
    n, m = sys.B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = sys.A
    M[:n, n:] = sys.B
    from scipy import linalg  # ~0.15 s of imports, not paid by an estimate

    E = linalg.expm(M * dt)
    return StateSpace(E[:n, :n], E[:n, n:], sys.C, sys.D, dt)


def d2c(sys: StateSpace) -> StateSpace:
    """Exact inverse of zero-order-hold discretisation.

    Computes ``log([[Ad, Bd], [0, I]]) / dt = [[A, B], [0, 0]]`` with the principal
    matrix logarithm, so that ``c2d(d2c(sys), sys.dt)`` returns ``sys``.

    Parameters
    ----------
    sys : StateSpace
        Discrete model (``sys.dt > 0``).

    Returns
    -------
    StateSpace
        Continuous model (``dt == 0``).

    Raises
    ------
    ConversionError
        If ``Ad`` has a pole at zero or on the negative real axis: no real
        continuous system maps to it under ZOH.

    Example
    -------
    >>> s = StateSpace([[0.9]], [[0.1]], [[1.0]], [[0.0]], dt=0.01)
    >>> c = d2c(s)
    >>> round(float(c.A[0, 0]), 4), round(float(c.B[0, 0]), 4)
    (-10.5361, 10.5361)
    """
    if not sys.dt > 0:
        raise ModelError("d2c expects a discrete model (dt > 0)")
    _check_zoh_poles(sys.A)
    n, m = sys.B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = sys.A
    M[:n, n:] = sys.B
    M[n:, n:] = np.eye(m)
    L = _real_log(M) / sys.dt
    return StateSpace(L[:n, :n], L[:n, n:], sys.C, sys.D, 0.0)


def _check_zoh_poles(A: FloatArray) -> None:
    """Refuse discrete poles no real continuous system maps to under ZOH."""
    poles = np.linalg.eigvals(A)
    scale = max(1.0, float(np.max(np.abs(poles))) if poles.size else 1.0)
    tol = 1e-12 * scale
    for z in poles:
        if abs(z) <= tol:
            raise ConversionError(
                f"discrete pole at z = {z:.3g} (at zero): no continuous-time "
                "equivalent under zero-order hold"
            )
        if z.real < 0 and abs(z.imag) <= 1e-9 * abs(z):
            raise ConversionError(
                f"discrete pole at z = {z.real:.6g} on the negative real axis: no real "
                "continuous-time equivalent under zero-order hold (sample faster, "
                "or lower the model order)"
            )


def _real_log(M: FloatArray, parts: list[Any] | None = None) -> FloatArray:
    """The principal logarithm of ``M``, refused when it is not real (no
    real ZOH equivalent); ``parts`` receives the eigen-decomposition used,
    when one was (see :func:`_logm`)."""
    L = _logm(M, parts)
    if np.iscomplexobj(L):
        if np.max(np.abs(L.imag)) > 1e-9 * max(1.0, float(np.max(np.abs(L.real)))):
            raise ConversionError("matrix logarithm is not real: no real ZOH equivalent")
        L = L.real
    return np.asarray(L, dtype=np.float64)


def _logm(M: FloatArray, parts: list[Any] | None = None
          ) -> NDArray[np.float64] | NDArray[np.complex128]:
    """Principal matrix logarithm, by eigen-decomposition when that is well
    conditioned (about 30x faster than the Schur-Pade method for the 3x3 matrices
    met here), else by :func:`scipy.linalg.logm`. ``parts``, when given,
    receives ``w, V, V⁻¹`` of the decomposition used (nothing in the other case)."""
    w, V = np.linalg.eig(M)
    try:
        Vi = np.linalg.inv(V)
    except np.linalg.LinAlgError:   # defective: no eigenvector basis
        Vi = None
    # the eigenvector basis's 1-norm condition number, from the inverse at hand
    # (the 2-norm one costs an SVD; the two agree within a factor of the size)
    if Vi is not None and float(np.linalg.norm(V, 1)) * float(np.linalg.norm(Vi, 1)) < 1e6:
        L = (V * np.log(w.astype(np.complex128))) @ Vi
        if parts is not None:
            parts.extend((w, V, Vi))
        return L.real if np.max(np.abs(L.imag)) < 1e-12 * max(1.0, np.max(np.abs(L))) else L
    from scipy import linalg  # the rare ill-conditioned case only

    out = linalg.logm(M)
    return np.asarray(out)


def _tf_to_ss(den: FloatArray, nums: FloatArray) -> tuple[FloatArray, ...]:
    """Controllable canonical realisation of a SIMO common-denominator TF."""
    den = np.asarray(den, dtype=np.float64)
    nums = np.atleast_2d(np.asarray(nums, dtype=np.float64))
    den = den / den[0]
    nums = nums / den[0]
    n = den.size - 1
    A = np.zeros((n, n))
    A[0, :] = -den[1:]
    A[1:, :-1] = np.eye(n - 1)
    B = np.zeros((n, 1))
    B[0, 0] = 1.0
    D = nums[:, :1].copy()
    C = nums[:, 1:] - D * den[1:]
    return A, B, C, D


def _ss_to_tf(A: FloatArray, B: FloatArray, C: FloatArray, D: FloatArray
              ) -> tuple[FloatArray, FloatArray]:
    """Common denominator and numerators of a single-input state-space model
    (the determinant identity; avoids scipy's warning on leading zero coefficients)."""
    den = _charpoly(A)
    nums = np.empty((C.shape[0], den.size))
    for j in range(C.shape[0]):
        nums[j] = _charpoly(A - B @ C[j : j + 1]) + (D[j, 0] - 1.0) * den
    return den, nums


def _charpoly(A: FloatArray) -> FloatArray:
    """Characteristic polynomial ``det(sI - A)`` (descending powers) of a
    small real matrix: up to order 3 its invariants (trace, sum of principal
    minors, determinant) in closed form, order 4 by the Faddeev-LeVerrier
    recursion (traces of products: no eigenvalue problem, as ``np.poly``
    solves), ``np.poly`` beyond."""
    n = A.shape[0]
    if n > 4:
        return np.asarray(np.real(np.poly(A)), dtype=np.float64)
    if n <= 3:   # the invariants in closed form, on plain floats (the common orders)
        a = A.tolist()
        if n == 0:
            return np.ones(1)
        if n == 1:
            return np.array([1.0, -a[0][0]])
        if n == 2:
            return np.array([1.0, -(a[0][0] + a[1][1]),
                             a[0][0] * a[1][1] - a[0][1] * a[1][0]])
        minors = (a[0][0] * a[1][1] - a[0][1] * a[1][0] + a[0][0] * a[2][2]
                  - a[0][2] * a[2][0] + a[1][1] * a[2][2] - a[1][2] * a[2][1])
        det = (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
               - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
               + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
        return np.array([1.0, -(a[0][0] + a[1][1] + a[2][2]), minors, -det])
    c = np.zeros(n + 1)
    c[0] = 1.0
    M = np.zeros_like(A)
    for k in range(1, n + 1):
        M = A @ M + c[k - 1] * np.eye(n)
        c[k] = -float(np.trace(A @ M)) / k
    return c


def tf_d2c(g: DiscreteTF) -> ContinuousTF:
    """Zero-order-hold inverse of a common-denominator discrete transfer function.

    Parameters
    ----------
    g : DiscreteTF
        Discrete model in q^-1.

    Returns
    -------
    ContinuousTF
        Continuous model with the same outputs, monic denominator in s.

    Example
    -------
    >>> gd = tf_c2d(ContinuousTF([1.0, 3.0, 2.0], [[0.0, 0.0, 2.0]]), 0.01)
    >>> np.round(tf_d2c(gd).den, 9)
    array([1., 3., 2.])
    """
    den, nums = d2c_coefficients(g.den, g.nums, g.dt)
    return ContinuousTF(den, nums, g.outputs, g.input)


def tf_d2c_jacobian(g: DiscreteTF) -> tuple[ContinuousTF, FloatArray]:
    """:func:`tf_d2c` and the exact Jacobian of the continuous coefficients.

    Parameters
    ----------
    g : DiscreteTF
        Discrete model in q^-1 (its denominator kept monic).

    Returns
    -------
    ContinuousTF
        As :func:`tf_d2c`.
    ndarray, shape (n + m n, n + m n)
        ``∂c/∂θ``: ``c`` the continuous ``den[1:]`` then each output's
        ``nums[j, 1:]``, ``θ`` the same of the discrete model (each direct
        term ``nums[j, 0]`` held). [continuous unit / discrete unit]

    Notes
    -----
    Derivatives in closed form, not by differences: the logarithm's Fréchet
    derivative ``L(M, E) = V (F ∘ V⁻¹EV) V⁻¹``, ``F`` the divided differences
    of ``log`` at the eigenvalues (Daleckii-Krein) [1]_, or, when the
    eigenvector basis is ill-conditioned, the corner of ``log`` of the block
    matrix ``[[M, E], [0, M]]``; then the characteristic polynomial's,
    ``∂c_k = -tr(N_(k-1) dX)`` with ``adj(sI - X) = Σ N_k s^(n-1-k)``
    (Jacobi's formula and the Faddeev-LeVerrier recursion).

    .. [1] N. J. Higham, *Functions of Matrices*, SIAM, 2008, thm. 3.11.

    Example
    -------
    >>> gd = tf_c2d(ContinuousTF([1.0, 3.0, 2.0], [[0.0, 0.0, 2.0]]), 0.01)
    >>> cont, J = tf_d2c_jacobian(gd)
    >>> J.shape, bool(np.all(np.isfinite(J)))
    ((4, 4), True)
    """
    A, B, C, D = _tf_to_ss(g.den, g.nums)
    n, m = A.shape[0], C.shape[0]
    _check_zoh_poles(A)
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n:], M[n, n] = A, B, 1.0
    parts: list[Any] = []
    L = _real_log(M, parts) / g.dt
    Ac, Bc = L[:n, :n], L[:n, n:]
    cden, nums = _ss_to_tf(Ac, Bc, C, D)
    if parts:
        w, V, Vi = parts
        F = _log_divided_differences(w)

        def dlog(k: int) -> FloatArray:   # dM = -E(0, k): one entry, an outer product
            inner = -np.outer(Vi[:, 0], V[k, :]) * F
            return np.asarray((V @ inner @ Vi).real, dtype=np.float64) / g.dt
    else:
        from scipy import linalg  # the rare ill-conditioned case only

        def dlog(k: int) -> FloatArray:
            big = np.zeros((2 * n + 2, 2 * n + 2))
            big[:n + 1, :n + 1] = big[n + 1:, n + 1:] = M
            big[0, n + 1 + k] = -1.0
            return np.asarray(np.real(linalg.logm(big))[:n + 1, n + 1:], dtype=np.float64) / g.dt
    N_den = _adjugate_terms(Ac, cden)
    N_num = [_adjugate_terms(Ac - Bc @ C[j:j + 1], nums[j] - (D[j, 0] - 1.0) * cden)
             for j in range(m)]
    J = np.zeros((n + m * n, n + m * n))
    for k in range(n):   # discrete den[k + 1]: A's first row and C (through D) move
        dL = dlog(k)
        dA, dB = dL[:n, :n], dL[:n, n:]
        dden = -(N_den @ dA.T.ravel())   # tr(N_k dA) for every k
        J[:n, k] = dden
        for j in range(m):
            dX = dA - dB @ C[j:j + 1]
            dX[:, k] += Bc[:, 0] * D[j, 0]
            J[n + j * n: n + (j + 1) * n, k] = (-(N_num[j] @ dX.T.ravel())
                                                + (D[j, 0] - 1.0) * dden)
    for j in range(m):   # discrete nums[j, i + 1]: C[j, i]; exact, as nums are linear in C
        J[n + j * n: n + (j + 1) * n, n + j * n: n + (j + 1) * n] = (
            N_num[j].reshape(n, n, n) @ Bc)[:, :, 0]
    return ContinuousTF(cden, nums, g.outputs, g.input), J


def _log_divided_differences(w: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """``F[i, j] = (log w_i - log w_j) / (w_i - w_j)``, ``1 / w_i`` where they
    meet (principal logarithms; close pairs by ``log1p`` of their ratio, with
    the branch of the two logarithms kept)."""
    w = w.astype(np.complex128)
    lw = np.log(w)
    d = w[:, None] - w[None, :]
    ratio = d / w[None, :]
    close = np.abs(ratio) < 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        dl = np.where(close, np.log1p(np.where(close, ratio, 0.0)), lw[:, None] - lw[None, :])
        turns = np.round(((lw[:, None] - lw[None, :]).imag - dl.imag) / (2 * np.pi))
        dl = dl + 2j * np.pi * turns
        F = np.where(d != 0, dl / np.where(d != 0, d, 1.0), 1.0 / w[None, :])
    return np.asarray(F, dtype=np.complex128)


def _adjugate_terms(X: FloatArray, c: FloatArray) -> FloatArray:
    """``N_0..N_(n-1)`` with ``adj(sI - X) = Σ_k N_k s^(n-1-k)``, from the
    characteristic polynomial ``c`` of ``X`` (``N_0 = I``,
    ``N_k = X N_(k-1) + c_k I``), each flattened: shape (n, n²), so that
    ``N @ dXᵀ.ravel()`` is every ``tr(N_k dX)``."""
    n = X.shape[0]
    eye = np.eye(n)
    N = np.empty((n, n, n))
    N[0] = eye
    for k in range(1, n):
        N[k] = X @ N[k - 1] + c[k] * eye
    return N.reshape(n, n * n)


def d2c_coefficients(den: FloatArray, nums: FloatArray, dt: float
                     ) -> tuple[FloatArray, FloatArray]:
    """:func:`tf_d2c` on bare coefficient arrays (no model objects).

    Returns the monic continuous denominator (descending powers of s) and the
    numerators, shape (n_outputs, n+1).
    """
    A, B, C, D = _tf_to_ss(den, nums)
    cs = d2c(StateSpace(A, B, C, D, dt))
    return _ss_to_tf(cs.A, cs.B, cs.C, cs.D)


def tf_c2d(g: ContinuousTF, dt: float) -> DiscreteTF:
    """Zero-order-hold discretisation of a common-denominator continuous transfer function.

    Parameters
    ----------
    g : ContinuousTF
        Continuous model.
    dt : float
        Sample time. [s]

    Returns
    -------
    DiscreteTF
        Discrete model in q^-1 with sample time ``dt``.

    Example
    -------
    >>> gd = tf_c2d(ContinuousTF([1.0, 1.0], [[0.0, 1.0]]), 0.1)
    >>> np.round(gd.den, 6)
    array([ 1.      , -0.904837])
    """
    A, B, C, D = _tf_to_ss(g.den, g.nums)
    ds = c2d(StateSpace(A, B, C, D, 0.0), dt)
    den, nums = _ss_to_tf(ds.A, ds.B, ds.C, ds.D)
    return DiscreteTF(den, nums, dt, g.outputs, g.input)
