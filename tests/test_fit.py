"""R_T² fit check (SPEC A4)."""

from __future__ import annotations

import numpy as np
import pytest

from condmon.identify import fit_check
from condmon.models import DiscreteTF


def _model() -> DiscreteTF:
    return DiscreteTF(np.array([1.0, -0.9]), np.array([[0.0, 1.0]]), 1e-3, ("y",))


def test_known_noise_gives_known_fit() -> None:
    g = _model()
    rng = np.random.default_rng(0)
    u = rng.standard_normal(100000)
    y = g.simulate(u)[:, 0]
    noise = rng.standard_normal(y.size) * np.std(y) * np.sqrt(0.05)
    fc = fit_check(g, u, y + noise)
    assert fc.r2["y"] == pytest.approx(0.95, abs=0.005)
    assert fc.accepted


def test_rejected_below_threshold() -> None:
    g = _model()
    u = np.random.default_rng(1).standard_normal(2000)
    y = g.simulate(u)[:, 0] + 3 * np.random.default_rng(2).standard_normal(2000)
    fc = fit_check(g, u, y, threshold=90.0)
    assert not fc.accepted and fc.fit_percent < 90.0


def test_unstable_model_is_rejected_not_nan() -> None:
    g = DiscreteTF(np.array([1.0, -1.5]), np.array([[0.0, 1.0]]), 1e-3)
    u = np.ones(500)
    fc = fit_check(g, u, u)
    assert fc.fit_percent == float("-inf") and not fc.accepted
