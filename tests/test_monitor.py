"""Baseline and fuzzy parameter monitor (SPEC A6)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from condmon.errors import ConfigError, DataError
from condmon.monitor import (
    Baseline, compute_symptoms, load_monitor_config, make_baseline, percent_change,
    symptom_degree,
)


def test_baseline_mean_and_sample_std() -> None:
    b = make_baseline(np.array([[1.0, 10.0], [1.2, 10.0], [1.4, 13.0]]), ["R", "D"])
    assert b.mean == pytest.approx((1.2, 11.0))
    assert b.std == pytest.approx((0.2, np.sqrt(3.0)))
    assert b.n == 3


def test_baseline_refuses_fewer_than_three_tests() -> None:
    with pytest.raises(DataError, match="at least 3 accepted healthy tests, got 2"):
        make_baseline([{"R": 1.0}, {"R": 1.1}])


def test_percent_change() -> None:
    b = Baseline(("R", "L"), (2.0, 1e-3), (0.01, 1e-5), 5)
    np.testing.assert_allclose(percent_change([[2.5, 0.8e-3]], b), [[25.0, -20.0]])


@pytest.mark.parametrize("r,w,r1,r2", [
    (30.0, 5.0, 20.0, 40.0), (10.0, 15.0, 20.0, 50.0), (-45.0, 3.0, 20.0, 50.0),
    (0.0, 0.0, 20.0, 40.0), (55.0, 10.0, 20.0, 50.0), (350.0, 40.0, 300.0, 600.0),
    (-25.0, 0.0, 20.0, 40.0), (19.0, 0.5, 20.0, 40.0),
])
def test_closed_form_matches_grid_max_min_composition(r: float, w: float, r1: float,
                                                      r2: float) -> None:
    """SymH/SymL against sup-min on a fine grid built with scikit-fuzzy."""
    fuzz = pytest.importorskip("skfuzzy")
    x = np.linspace(-1000.0, 1000.0, 2_000_001)
    S = fuzz.trimf(x, [r - w, r, r + w]) if w > 0 else np.isclose(x, r, atol=5e-4).astype(float)
    high = fuzz.trapmf(x, [r1, r2, 1e9, 1e9])
    low = fuzz.trapmf(x, [-1e9, -1e9, -r2, -r1])
    h, lo = symptom_degree(r, w, r1, r2)
    tol = 2e-3 / max(w, 1e-3) + 1e-3
    assert float(h) == pytest.approx(float(np.max(np.minimum(S, high))), abs=tol)
    assert float(lo) == pytest.approx(float(np.max(np.minimum(S, low))), abs=tol)


def test_symptoms_are_vectorised_over_tests_and_parameters() -> None:
    b = Baseline(("R", "L", "D"), (1.0, 1e-3, 1e-4), (0.005, 1e-5, 1.7e-5), 5)
    vals = np.array([[1.0, 1e-3, 1e-4], [1.4, 1.6e-3, 1e-4], [0.55, 1e-3, 7e-4]])
    s = compute_symptoms(vals, b)
    assert s.high.shape == (3, 3)
    assert np.all(s.high[0] == 0) and np.all(s.low[0] == 0)
    assert s.high[1, 0] == 1.0 and s.high[1, 1] == 1.0
    assert s.low[2, 0] == 1.0 and s.high[2, 2] == 1.0
    assert s.width[2] == pytest.approx(2 * 17.0)


def test_shipped_breakpoints_are_the_reference_table() -> None:
    cfg = load_monitor_config()
    assert (cfg.r1["R"], cfg.r2["R"]) == (20.0, 40.0)
    assert (cfg.r1["L"], cfg.r2["L"]) == (20.0, 50.0)
    assert (cfg.r1["D"], cfg.r2["D"]) == (300.0, 600.0)
    assert cfg.k == 2.0


def test_bad_monitor_file_is_explained(tmp_path: Path) -> None:
    p = tmp_path / "m.toml"
    p.write_text("[breakpoints]\nR = { r1 = 40.0, r2 = 20.0 }\n")
    with pytest.raises(ConfigError, match="r1 < r2"):
        load_monitor_config(p)
    b = Baseline(("Q",), (1.0,), (0.1,), 3)
    with pytest.raises(ConfigError, match=r"no breakpoints for \['Q'\]"):
        compute_symptoms([1.0], b)
