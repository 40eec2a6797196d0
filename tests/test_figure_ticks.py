"""Figures stay readable at any number of tests: tick labels never overlap.

At about 40 tests the report's fit and trend figures had labelled every test,
and the labels merged into one black bar. Drawn at 10, 100 and 1,000 tests,
on an id axis and on a date axis, no two labels may overlap, and there are
labels to read.
"""

from __future__ import annotations

import numpy as np
import pytest

from condmon.report.figures import fit_figure, trend_figure
from condmon.report.trends import FitData, TrendData


def _x(n: int, dated: bool) -> np.ndarray:
    if dated:
        return (np.datetime64("2026-01-01T00:00") + np.arange(n) * np.timedelta64(6, "h"))
    return np.arange(1, n + 1, dtype=np.float64) * 3   # ids with gaps


def _trend(n: int, dated: bool) -> TrendData:
    rng = np.random.default_rng(n)
    change = rng.normal(0.0, 3.0, n)
    return TrendData("R", tuple(range(3, 3 * n + 1, 3)), _x(n, dated),
                     "test date (UTC)" if dated else "test #", change, np.full(n, 2.0),
                     np.full(n, 0.5), np.zeros(n), np.zeros(n), ("go",) * n, 4.0, 15.0, 30.0,
                     2.0)


def _texts(fig: object) -> tuple[list[tuple[float, float, float, float]], int]:
    """Every visible, non-empty upright text's box on the canvas (tick labels
    and point annotations), and how many slanted tick labels sit closer than
    their own height to the next one (parallel lines of text: their upright
    boxes overlap while the text does not)."""
    import math

    fig.canvas.draw()   # type: ignore[attr-defined]
    renderer = fig.canvas.get_renderer()   # type: ignore[attr-defined]
    upright, crowded = [], 0
    for ax in fig.axes:   # type: ignore[attr-defined]
        if not ax.get_visible():
            continue
        slanted = []
        lo, hi = sorted(ax.get_xlim())
        ticks = [t for t, at in zip(ax.get_xticklabels(), ax.get_xticks())
                 if lo <= at <= hi]   # matplotlib draws no label beyond the limits
        texts = [t for t in ticks if t.get_visible() and t.get_text()]
        texts += [t for t in ax.texts if t.get_visible() and t.get_text()]
        for t in texts:
            b = t.get_window_extent(renderer)
            if t.get_rotation() % 180:
                slanted.append((b.x0, t.get_rotation(), t.get_fontsize() * fig.dpi / 72))
            else:
                upright.append((b.x0, b.y0, b.x1, b.y1))
        slanted.sort()
        for (x0, angle, height), (x1, _, _) in zip(slanted, slanted[1:]):
            if (x1 - x0) * math.sin(math.radians(angle)) < 0.9 * height:
                crowded += 1
        upright += [(x, 0.0, x + 1.0, 1.0) for x, _, _ in slanted[:1]]   # counted as there
    return upright, crowded


def _overlaps(boxes: list[tuple[float, float, float, float]]) -> int:
    bad = 0
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            if a[0] < b[2] - 0.5 and b[0] < a[2] - 0.5 and a[1] < b[3] - 0.5 and b[1] < a[3] - 0.5:
                bad += 1
    return bad


@pytest.mark.parametrize("dated", [False, True], ids=["ids", "dates"])
@pytest.mark.parametrize("n", [10, 100, 1000])
def test_trend_and_fit_labels_never_overlap(n: int, dated: bool) -> None:
    trend = _trend(n, dated)
    fit = FitData(trend.test_ids, trend.x, trend.xlabel, np.full(n, 95.0), ("go",) * n)
    for fig in (trend_figure([trend]), fit_figure(fit, 90.0)):
        boxes, crowded = _texts(fig)
        assert len(boxes) >= 3, "there are labels to read"
        assert _overlaps(boxes) == 0 and crowded == 0


def test_each_panel_is_coloured_by_its_own_symptom() -> None:
    """A check made no-go by friction alone does not paint R red."""
    from matplotlib.colors import to_hex

    from condmon.report.figures import STATUS_COLOURS

    n = 3
    status = ("go", "no-go", "no-go")
    r = TrendData("R", (4, 5, 6), np.arange(4.0, 7.0), "test #", np.array([0.5, 1.0, 0.2]),
                  np.full(n, 2.0), np.full(n, 0.5), np.zeros(n), np.zeros(n), status, 4.0,
                  15.0, 30.0, 2.0)
    d = TrendData("D", (4, 5, 6), np.arange(4.0, 7.0), "test #", np.array([1.0, 80.0, 90.0]),
                  np.full(n, 2.0), np.full(n, 0.5), np.array([0.0, 1.0, 1.0]), np.zeros(n),
                  status, 4.0, 15.0, 30.0, 2.0)
    assert r.panel_status == ("go", "go", "go") and d.panel_status == status
    fig = trend_figure([r, d])
    colours = []
    for ax in fig.axes[:1]:   # R's panel: every marker green
        for line in ax.get_lines():
            if line.get_marker() == "o":
                colours.append(to_hex(line.get_markeredgecolor()))
    assert colours and set(colours) == {STATUS_COLOURS["go"]}


def test_a_ran_away_or_non_finite_estimate_is_shown_as_such() -> None:
    from condmon.report.tables import SuspectCell, estimate_text

    cell = SuspectCell("Dm", 4.6e47, 8.2e-5, "m^3/rad", 5.6e53, 3.0, False, False)
    assert cell.row[1] == "ran away" and cell.row[4] == "ran away"
    assert "e+47" not in " ".join(cell.row)
    assert estimate_text(float("nan"), None) == "not finite"
    assert estimate_text(1.05e-4, 28.0) == "0.000105"


def test_no_samples_since_is_read_from_the_samples() -> None:
    """The live page's stale line gives the last sample's arrival, not the
    page's start; a unit heard of only by its retained status says so."""
    import time

    from condmon.report.live import LiveFeed

    feed = LiveFeed.offline(stale_after=5.0)
    feed.take("condmon/A/status", b'{"unit": "A", "status": "go"}')
    feed.take("condmon/B/status", b'{"unit": "B", "status": "go"}')
    feed.take("condmon/A/samples", b"{}")
    feed._sampled["A"] = time.time() - 3600.0   # its last sample: an hour ago
    feed.mark_stale(time.monotonic() + 60.0)
    a, b = feed.status("A"), feed.status("B")
    assert a is not None and b is not None
    hour_ago = time.strftime("%Y-%m-%d %H:%M", time.gmtime(time.time() - 3600.0))
    assert a["status"] == "stale" and f"no samples since {hour_ago}" in a["reason"]
    assert "since this page started" in b["reason"] and "not known" in b["reason"]
