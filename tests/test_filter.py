"""The linear filter (scipy's C routine loaded on its own, and the plain-numpy
fallback) against scipy.signal.lfilter (known truth)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter as scipy_lfilter

from condmon._filter import c_filter, lfilter, numpy_lfilter

BOTH = pytest.mark.parametrize("lfilter", [lfilter, numpy_lfilter], ids=["c", "numpy"])


def test_scipys_c_routine_loads_without_importing_scipy_signal() -> None:
    import subprocess
    import sys

    code = ("import sys; from condmon._filter import c_filter, lfilter; "
            "assert c_filter() is not None; lfilter([1.0], [1.0, -0.5], [1.0, 0.0]); "
            "print('scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
    assert c_filter() is not None


@BOTH
@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), nb=st.integers(1, 6), order=st.integers(0, 8),
       n=st.integers(1, 900), layout=st.sampled_from(["1d", "columns", "rows"]))
def test_same_as_scipy_for_stable_filters(  # type: ignore[no-untyped-def]
        lfilter, seed: int, nb: int, order: int, n: int, layout: str) -> None:
    rng = np.random.default_rng(seed)
    b = rng.standard_normal(nb)
    a = np.real(np.poly(rng.uniform(-0.995, 0.995, order))) * rng.uniform(0.5, 2.0)
    x, axis = {"1d": (rng.standard_normal(n), -1),
               "columns": (rng.standard_normal((n, 3)), 0),
               "rows": (rng.standard_normal((2, n)), -1)}[layout]
    want = scipy_lfilter(b, a, x, axis=axis)
    got = lfilter(b, a, x, axis=axis)
    assert got.shape == want.shape and got.dtype == np.float64
    # two float64 recursions of an order-8 filter with poles up to 0.995 part by
    # rounding, amplified by the filter's gain: 1e-8 of the output's size (a
    # hypothesis example, order 6, differed by 1.1e-9 of it)
    assert np.max(np.abs(got - want)) <= 1e-8 * (1.0 + np.max(np.abs(want)))


@BOTH
@pytest.mark.parametrize("pole", [0.9999, 1.0, 1.002])
def test_marginal_and_slightly_unstable_filters(  # type: ignore[no-untyped-def]
        lfilter, pole: float) -> None:
    x = np.random.default_rng(1).standard_normal(5000)
    a = np.poly([pole, 0.5])
    want = scipy_lfilter([0.0, 1.0], a, x)
    assert np.allclose(lfilter([0.0, 1.0], a, x), want, rtol=1e-9,
                       atol=1e-9 * np.max(np.abs(want)))


@BOTH
def test_leading_coefficient_normalised_and_fir_only(  # type: ignore[no-untyped-def]
        lfilter) -> None:
    x = np.arange(10.0)
    assert np.allclose(lfilter([2.0, 1.0], [2.0], x), scipy_lfilter([2.0, 1.0], [2.0], x))
    assert np.allclose(lfilter([1.0], [2.0, -1.0, 0.0], x), scipy_lfilter([1.0], [2.0, -1.0], x))


@BOTH
def test_bad_coefficients_refused(lfilter) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match="a\\[0\\] non-zero"):
        lfilter([1.0], [0.0, 1.0], np.ones(3))


@BOTH
def test_an_all_pole_filter_runs_in_place_when_asked_and_allowed(  # type: ignore[no-untyped-def]
        lfilter) -> None:
    from scipy.signal import lfilter as reference

    x = np.random.default_rng(3).standard_normal((70_000, 3))   # past a pass at once
    want = reference([1.0], [1.0, -1.4, 0.43], x, axis=0)
    kept = x.copy()
    out = lfilter([1.0], [1.0, -1.4, 0.43], x, axis=0, overwrite_x=True)
    assert np.shares_memory(out, x) and np.allclose(out, want, rtol=1e-10, atol=1e-10)
    y = kept.copy()
    out = lfilter([1.0, 0.5], [1.0, -0.5], y, axis=0, overwrite_x=True)   # a numerator: a copy
    assert not np.shares_memory(out, y) and np.array_equal(y, kept)
    out = lfilter([1.0], [1.0, -0.5], kept[:, 0], overwrite_x=False)
    assert not np.shares_memory(out, kept)


def test_a_changed_or_missing_c_routine_leaves_the_work_to_numpy(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import sys
    import types

    import condmon._filter as filt

    wrong = types.ModuleType("scipy.signal._sigtools")
    wrong._linear_filter = lambda b, a, x, axis: np.zeros_like(x)   # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "scipy.signal._sigtools", wrong)
    c_filter.cache_clear()
    try:
        assert c_filter() is None    # the known impulse response was not returned
        gone = types.ModuleType("scipy.signal._sigtools")   # no routine at all
        monkeypatch.setitem(sys.modules, "scipy.signal._sigtools", gone)
        c_filter.cache_clear()
        assert c_filter() is None
        x = np.random.default_rng(4).standard_normal(300)
        want = scipy_lfilter([0.0, 1.0], [1.0, -0.8], x)
        assert np.allclose(filt.lfilter([0.0, 1.0], [1.0, -0.8], x), want, rtol=1e-12,
                           atol=1e-12)
    finally:
        monkeypatch.undo()
        c_filter.cache_clear()
    assert c_filter() is not None


@BOTH
def test_a_fortran_ordered_array_is_filtered_in_place(  # type: ignore[no-untyped-def]
        lfilter) -> None:
    x = np.asfortranarray(np.random.default_rng(5).standard_normal((3000, 4)))
    want = scipy_lfilter([1.0], [1.0, -1.6, 0.7], x, axis=0)
    out = lfilter([1.0], [1.0, -1.6, 0.7], x, axis=0, overwrite_x=True)
    assert np.shares_memory(out, x) and np.allclose(x, want, rtol=1e-12, atol=1e-12)


def test_sriv_gives_the_same_estimate_with_the_numpy_filter(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """SRIV filters part of its buffer in place: the fallback filter must too."""
    import condmon._filter as filt
    from condmon.identify import sriv

    rng = np.random.default_rng(6)
    u = rng.standard_normal(3000)
    x = scipy_lfilter([1.0], [1.0, -1.2, 0.5], u)
    y = np.column_stack([scipy_lfilter([0.0, 0.5, 0.2], [1.0], x),
                         scipy_lfilter([0.0, 0.1, 0.3], [1.0], x)])
    y += 0.05 * rng.standard_normal(y.shape)
    with_c = sriv(u, y, 2)
    monkeypatch.setattr(filt, "c_filter", lambda: None)
    with_numpy = sriv(u, y, 2)
    assert with_numpy.iterations == with_c.iterations
    assert np.allclose(with_numpy.theta, with_c.theta, rtol=1e-9, atol=1e-12)
