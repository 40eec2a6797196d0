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
