"""ZOH discretisation and its exact inverse (reference: scipy.signal.cont2discrete)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from condmon.errors import ConversionError
from condmon.models import ContinuousTF, DiscreteTF, StateSpace, c2d, d2c, tf_c2d, tf_d2c

SYSTEMS = [
    # (den, nums) continuous, descending powers; sample time
    ([1.0, 835.0, 41250.0], [[0.0, 833.3, 1.667], [0.0, 0.0, 833333.0]], 1e-3),  # DC motor
    ([1.0, 835.0, 41250.0], [[0.0, 833.3, 1.667], [0.0, 0.0, 833333.0]], 2e-4),
    ([1.0, 2.0, 101.0], [[0.0, 1.0, 3.0]], 0.05),                               # complex
    ([1.0, 2.0, 101.0], [[0.0, 1.0, 3.0]], 1e-3),
    ([1.0, 6.0, 11.0, 6.0], [[0.0, 0.0, 1.0, 2.0], [0.0, 1.0, 0.0, 5.0]], 0.05),  # 3rd order
    ([1.0, 0.5], [[2.0, 1.0]], 0.1),                                            # biproper
]


@pytest.mark.parametrize("den,nums,dt", SYSTEMS)
def test_tf_c2d_matches_scipy(den: list[float], nums: list[list[float]], dt: float) -> None:
    g = ContinuousTF(np.array(den), np.array(nums))  # type: ignore[arg-type]
    gd = tf_c2d(g, dt)
    for j, num in enumerate(nums):
        nd, dd, _ = signal.cont2discrete((np.trim_zeros(num, "f"), den), dt, method="zoh")
        nd = np.ravel(nd)
        np.testing.assert_allclose(gd.den, dd, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(gd.nums[j, -nd.size:], nd, rtol=1e-9,
                                   atol=1e-12 * np.max(np.abs(nd)))


@pytest.mark.parametrize("den,nums,dt", SYSTEMS)
def test_d2c_inverts_scipy_cont2discrete(den: list[float], nums: list[list[float]],
                                        dt: float) -> None:
    """d2c of scipy's ZOH discretisation returns the original to 1e-9 relative."""
    rows = []
    dd = None
    for num in nums:
        nd, dd, _ = signal.cont2discrete((np.trim_zeros(num, "f"), den), dt, method="zoh")
        nd = np.ravel(nd)
        rows.append(np.r_[np.zeros(len(den) - nd.size), nd])
    assert dd is not None
    gc = tf_d2c(DiscreteTF(np.asarray(dd), np.array(rows), dt, tuple(f"y{j}" for j in range(len(nums)))))
    np.testing.assert_allclose(gc.den, den, rtol=1e-9)
    scale = np.max(np.abs(nums))
    np.testing.assert_allclose(gc.nums, nums, rtol=1e-9, atol=1e-9 * scale)


def test_d2c_state_space_round_trip_with_correct_input_matrix() -> None:
    rng = np.random.default_rng(3)
    A = np.array([[-3.0, 1.0, 0.0], [-1.0, -3.0, 0.5], [0.0, 0.0, -10.0]])
    B = rng.standard_normal((3, 2))
    C = rng.standard_normal((1, 3))
    D = np.zeros((1, 2))
    sysd = c2d(StateSpace(A, B, C, D), 0.02)
    back = d2c(sysd)
    np.testing.assert_allclose(back.A, A, rtol=1e-9, atol=1e-9)
    # B must come from the log of the augmented matrix; log(Ad) alone cannot give it.
    np.testing.assert_allclose(back.B, B, rtol=1e-9, atol=1e-9)


def test_d2c_first_order_analytic() -> None:
    a, b, dt = -4.0, 2.0, 0.1
    sysd = StateSpace([[np.exp(a * dt)]], [[b / a * (np.exp(a * dt) - 1)]], [[1.0]], [[0.0]], dt)
    c = d2c(sysd)
    assert c.A[0, 0] == pytest.approx(a, rel=1e-12)
    assert c.B[0, 0] == pytest.approx(b, rel=1e-12)


def test_d2c_refuses_negative_real_pole() -> None:
    g = DiscreteTF(np.array([1.0, 0.5]), np.array([[0.0, 1.0]]), 0.01)
    with pytest.raises(ConversionError, match="negative real axis"):
        tf_d2c(g)


def test_d2c_refuses_pole_at_zero() -> None:
    g = DiscreteTF(np.array([1.0, 0.0]), np.array([[0.0, 1.0]]), 0.01)
    with pytest.raises(ConversionError, match="at zero"):
        tf_d2c(g)


def test_conversion_errors_are_value_errors() -> None:
    with pytest.raises(ValueError):
        tf_d2c(DiscreteTF(np.array([1.0, 0.3]), np.array([[0.0, 1.0]]), 0.01))


def test_to_control_interop() -> None:
    control = pytest.importorskip("control")
    g = ContinuousTF(np.array([1.0, 3.0, 2.0]), np.array([[0.0, 1.0, 1.0], [0.0, 0.0, 2.0]]),
                     ("I", "omega"), "V")
    gd = tf_c2d(g, 0.01)
    gc, gdc = g.to_control(), gd.to_control()
    assert gdc.dt == 0.01 and gdc.output_labels == ["I", "omega"]
    w = np.array([0.5, 5.0, 50.0])
    for j in range(2):
        ref = control.c2d(gc[j, 0], 0.01, method="zoh")
        np.testing.assert_allclose(gdc[j, 0](np.exp(1j * w * 0.01)),
                                   ref(np.exp(1j * w * 0.01)), rtol=1e-9)


def test_the_characteristic_polynomial_without_eigenvalues_is_numpys() -> None:
    import numpy as np

    from condmon.models.conversion import _charpoly

    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 4, 6):
        for _ in range(50):
            A = rng.normal(0.0, 1.0, (n, n)) * 10.0 ** rng.uniform(-2, 4)
            want = np.real(np.poly(A))
            assert np.allclose(_charpoly(A), want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))
    # a DC motor's state matrix: s^2 + (R/L + D/J) s + (R D + Ke Kt) / (L J)
    R, L, J, D, Ke, Kt = 1.0, 1.2e-3, 5e-5, 1e-4, 0.0475, 0.05
    A = np.array([[-R / L, -Ke / L], [Kt / J, -D / J]])
    assert np.allclose(_charpoly(A), [1.0, R / L + D / J, (R * D + Ke * Kt) / (L * J)],
                       rtol=1e-13)


def _coefficients(g: DiscreteTF) -> np.ndarray:
    c = tf_d2c(g)
    return np.r_[c.den[1:], c.nums[:, 1:].ravel()]


@pytest.mark.parametrize("den,nums,dt", [*SYSTEMS, ([1.0, 9.0, 27.0, 27.0],   # a triple pole:
                                                    [[0.0, 1.0, 2.0, 3.0]], 0.01)])  # no eigenbasis
def test_the_zoh_inverse_jacobian_is_its_differences(den: list[float], nums: list[list[float]],
                                                     dt: float) -> None:
    """The closed-form Jacobian of the ZOH inverse's coefficients equals
    central differences of tf_d2c (each direct term held), and the model is
    tf_d2c's."""
    from condmon.models.conversion import tf_d2c_jacobian

    gd = tf_c2d(ContinuousTF(np.array(den), np.array(nums)), dt)  # type: ignore[arg-type]
    cont, J = tf_d2c_jacobian(gd)
    ref = tf_d2c(gd)
    np.testing.assert_array_equal(cont.den, ref.den)
    np.testing.assert_array_equal(cont.nums, ref.nums)
    n = gd.order
    theta = np.r_[gd.den[1:], gd.nums[:, 1:].ravel()]

    def at(th: np.ndarray) -> np.ndarray:
        nums_d = np.column_stack([gd.nums[:, 0], th[n:].reshape(-1, n)])
        return _coefficients(DiscreteTF(np.r_[1.0, th[:n]], nums_d, dt, gd.outputs))

    fd = np.empty_like(J)
    for k in range(theta.size):
        h = 1e-6 * max(abs(theta[k]), 1e-3)
        step = np.zeros(theta.size)
        step[k] = h
        fd[:, k] = (at(theta + step) - at(theta - step)) / (2 * h)
    scale = np.max(np.abs(fd), axis=1, keepdims=True)
    assert np.max(np.abs(J - fd) / scale) < 1e-5


def test_the_zoh_inverse_jacobian_of_a_first_order_lag_is_analytic() -> None:
    """b q⁻¹ / (1 - a q⁻¹) is K p / (s + p) with a = exp(-p dt), b = K (1 - a):
    p = -ln(a)/dt and K p = -b ln(a) / ((1 - a) dt), differentiated by hand
    (θ = [-a, b])."""
    from condmon.models.conversion import tf_d2c_jacobian

    a, b, dt = 0.9, 0.3, 0.01
    _, J = tf_d2c_jacobian(DiscreteTF(np.array([1.0, -a]), np.array([[0.0, b]]), dt))
    la = np.log(a)
    want = np.array([[1.0 / (a * dt), 0.0],
                     [b / dt * ((1.0 - a) / a + la) / (1.0 - a) ** 2, -la / ((1.0 - a) * dt)]])
    np.testing.assert_allclose(J, want, rtol=1e-12)
