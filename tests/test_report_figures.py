"""The report's figures, checked by their geometry: no legend on the axes (so
none can cover a point), every isolation estimate inside its axis (the
+292 % leakage of a real isolation included), each symptom bar on its test's
tick; and the error bar each figure and page states."""

from __future__ import annotations

import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from condmon.report import write_report
from condmon.report.trends import IsolationTrend
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

ACT, HST = "EMA-1", "HST-1"


@pytest.fixture(scope="module")
def history(tmp_path_factory: pytest.TempPathFactory, rig: ActuatorRig) -> str:
    """An actuator with dated healthy and worn checks; an HST unit whose one
    isolation estimated the motor leakage resistance far from nominal."""
    from condmon.diagnose.isolation import isolate
    from condmon.io.digest import content_hash
    from condmon.models.registry import load_plant_model
    from condmon.simulate.plant import simulate_plant

    db = str(tmp_path_factory.mktemp("figs") / "h.db")
    with open_store(db) as store:
        healthy = [simulate_actuator(rig, seed=s) for s in range(1, 5)]
        for s, df in enumerate(healthy, 1):
            df.attrs["source"] = f"h{s}.csv"
        add_baseline_tests(store, ACT, healthy, test_date="2026-03-01")
        for day, (faults, seed) in enumerate([([], 21), (["D=*3"], 22), (["D=*7"], 23),
                                              (["R=*0.7"], 24)], 2):
            rec = simulate_actuator(rig.with_faults(faults), seed=seed)
            rec.attrs["source"] = f"c{seed}.csv"
            check_test(store, ACT, rec, test_date=f"2026-04-{day:02d}")
        hst = load_plant_model("hst")
        rec = simulate_plant(hst, ["Rlkgm=+290%@10s"], seed=3)
        store.add_isolation(HST, isolate(rec, hst, workers=1), model="hst",
                            source="hst-leak.csv", digest=content_hash(rec))
    return db


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Any]]:
    """Every figure saved meanwhile, laid out and drawn as it was written."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figs: list[Any] = []
    save = Figure.savefig

    def keep(self: Any, *args: Any, **kwargs: Any) -> None:
        save(self, *args, **kwargs)
        if not isinstance(self.canvas, FigureCanvasAgg):
            FigureCanvasAgg(self)
        self.canvas.draw()
        figs.append(self)

    monkeypatch.setattr(Figure, "savefig", keep)
    yield figs


def _titled(figs: list[Any], text: str) -> Any:
    """The figure whose title (or an axes' title) holds ``text``."""
    for fig in figs:
        titles = [t.get_text() for t in fig.texts] + [ax.get_title() for ax in fig.axes]
        if any(text in t for t in titles):
            return fig
    raise AssertionError(f"no figure titled {text!r}")


def _points(ax: Any) -> np.ndarray[Any, Any]:
    """Display coordinates of every data point of every line and bar top of ``ax``
    (also those outside its limits, which are clipped)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    out = []
    for line in ax.get_lines():
        if isinstance(line, Line2D) and len(line.get_xdata()):
            xy = np.column_stack([ax.convert_xunits(line.get_xdata()),
                                  np.asarray(line.get_ydata(), dtype=np.float64)])
            xy = xy.astype(np.float64)
            out.append(ax.transData.transform(xy[np.isfinite(xy).all(axis=1)]))
    for bar in ax.patches:
        if isinstance(bar, Rectangle) and bar.get_height():
            out.append(ax.transData.transform([[bar.get_x() + bar.get_width() / 2,
                                                bar.get_y() + bar.get_height()]]))
    return np.concatenate(out) if out else np.zeros((0, 2))


def _assert_legends_outside(fig: Any) -> None:
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend())]
    assert legends, "a figure without a legend"
    for leg in legends:
        box = leg.get_window_extent()
        for ax in fig.axes:
            if not ax.axison:
                continue
            assert not box.overlaps(ax.get_window_extent()), (leg, ax.get_ylabel())
            shown = [p for p in _points(ax) if ax.get_window_extent().contains(*p)]  # not clipped
            inside = [p for p in shown if box.contains(*p)]
            assert not inside, (ax.get_ylabel(), inside[:3])


def test_no_legend_covers_data(history: str, tmp_path: Path, drawn: list[Any]) -> None:
    with open_store(history, create=False) as store:
        write_report(store, ACT, tmp_path)
        write_report(store, HST, tmp_path)
    names = ("Change against", "Model fit", "Fuzzy symptoms", "Suspects'")
    for name in names:
        _assert_legends_outside(_titled(drawn, name))


def test_isolation_figures_legends_are_outside(history: str, tmp_path: Path,
                                               drawn: list[Any]) -> None:
    from condmon.diagnose.isolation import isolate
    from condmon.models.registry import load_plant_model
    from condmon.report.isolation_figures import write_isolation_figures
    from condmon.simulate.plant import simulate_plant

    hst = load_plant_model("hst")
    rec = simulate_plant(hst, ["Rv=+40%@10s"], seed=4)
    res = isolate(rec, hst, workers=1)
    files = write_isolation_figures(res, hst, rec[list(hst.sensor_names)].to_numpy(), tmp_path)
    assert [f.name for f in files] == ["residuals.png", "model-errors.png"]
    for fig in drawn:
        _assert_legends_outside(fig)


def _assert_inside(ax: Any, values: np.ndarray[Any, Any]) -> None:
    """Every finite value within the y limits, and every marker whole inside the axes."""
    lo, hi = ax.get_ylim()
    finite = values[np.isfinite(values)]
    assert finite.size and (finite > lo).all() and (finite < hi).all(), (finite, lo, hi)
    box = ax.get_window_extent()
    for line in ax.get_lines():
        if line.get_marker() in (None, "None", "", " "):
            continue
        r = line.get_markersize() / 2 * ax.figure.dpi / 72  # [px]
        xy = np.column_stack([ax.convert_xunits(line.get_xdata()),
                              np.asarray(line.get_ydata(), dtype=np.float64)]).astype(float)
        for x, y in ax.transData.transform(xy[np.isfinite(xy).all(axis=1)]):
            assert box.x0 + r <= x <= box.x1 - r and box.y0 + r <= y <= box.y1 - r, (
                line.get_label(), x, y, box)


def test_every_isolation_estimate_is_inside_its_axis(history: str, tmp_path: Path,
                                                     drawn: list[Any]) -> None:
    from condmon.report.figures import plot_isolation_trends

    with open_store(history, create=False) as store:
        page = write_report(store, HST, tmp_path)
    iso = page.isolations
    assert iso is not None and iso.change["Rlkgm"][0] > 250  # the estimate far off nominal
    _assert_inside(_titled(drawn, "Suspects'").axes[0], np.concatenate(
        list(iso.change.values())))
    # a leak a thousandfold (+99 900 %) and one almost closed (-99.9 %) on one axis
    x = np.array([1.0, 2.0, 3.0])
    many = IsolationTrend((1, 2, 3), x, "isolation #", ("no-go", "no-go", "go"),
                          {"Rlkgp": np.array([99900.0, -99.9, np.nan]),
                           "Dm": np.array([-3.0, -50.0, 289.9])},
                          {"Rlkgp": np.array([True, False, False]),
                           "Dm": np.array([False, True, False])})
    plot_isolation_trends(many, io.BytesIO())
    _assert_inside(drawn[-1].axes[0], np.concatenate(list(many.change.values())))


def test_symptom_bars_sit_on_their_ticks(history: str, tmp_path: Path,
                                         drawn: list[Any]) -> None:
    from matplotlib.patches import Rectangle

    with open_store(history, create=False) as store:
        page = write_report(store, ACT, tmp_path)
    ids = page.trends[0].test_ids
    assert len(ids) == 4
    fig = _titled(drawn, "Fuzzy symptoms")
    bars = 0
    for ax in (a for a in fig.axes if a.axison):
        label = ax.xaxis.get_major_formatter()
        ticks = {label(t, j): float(t) for j, t in enumerate(ax.get_xticks())}
        for rect in (p for p in ax.patches if isinstance(p, Rectangle)):
            centre = rect.get_x() + rect.get_width() / 2
            assert any(abs(centre - t) < 1e-9 for t in ticks.values()), (centre, ticks)
            bars += rect.get_height() != 0
        # the bar of each test on the tick labelled with its id
        centres = sorted({round(r.get_x() + r.get_width() / 2, 9) for r in ax.patches})
        assert centres == [ticks[f"#{i}"] for i in ids]
    assert bars >= 2  # the worn checks' D and R symptoms


def test_figures_and_pages_state_one_error_bar(history: str, tmp_path: Path,
                                               drawn: list[Any]) -> None:
    from condmon.report.trends import error_bar

    with open_store(history, create=False) as store:
        page = write_report(store, ACT, tmp_path)
    k = page.trends[0].k
    title = " ".join(t.get_text() for t in _titled(drawn, "Change against").texts)
    assert f"error bars: {error_bar(k)}" in title
    html = page.html.read_text()
    assert error_bar(k, words=True).replace("'", "&#x27;") in html
    d = next(t for t in page.trends if t.parameter == "D")
    with open_store(history, create=False) as store:
        hist = store.history(ACT)
        used = {b.id: b.baseline for b in store.baselines(ACT)}
    for i, tid in enumerate(d.test_ids):
        b = used[int(hist.loc[tid, "baseline_id"])]
        j = b.parameters.index("D")
        want = k * 100 * max(b.std[j], hist.loc[tid, "D_se"]) / abs(b.mean[j])
        assert d.width[i] == pytest.approx(want)
    assert isinstance(hist.loc[d.test_ids[0], "date"], pd.Timestamp)


def test_the_forecast_band_is_drawn_and_named(tmp_path: Path, wearing: tuple[Path, float],
                                              drawn: list[Any]) -> None:
    """A unit whose friction rises over dated checks (conftest's wearing history):
    its trend figure draws the forecast band on the friction panel only, and the
    legend (below the axes, covering nothing) names it; a stable unit's figure
    has none."""
    import shutil

    from matplotlib.collections import PolyCollection

    from condmon.report.trends import FORECAST_LABEL

    db = str(tmp_path / "wear.db")
    shutil.copy(wearing[0], db)
    with open_store(db) as store:
        write_report(store, "WEAR", tmp_path / "w")
        wear = _titled(drawn, "Change against")
        drawn.clear()
        write_report(store, "STABLE", tmp_path / "s")
        stable = _titled(drawn, "Change against")
    _assert_legends_outside(wear)
    (legend,) = wear.legends
    assert FORECAST_LABEL in [t.get_text() for t in legend.get_texts()]
    banded = [ax.get_ylabel() for ax in wear.axes
              if any(c.get_label() == FORECAST_LABEL for c in ax.collections
                     if isinstance(c, PolyCollection))]
    assert banded == ["D change [%]"]
    d = next(ax for ax in wear.axes if ax.get_ylabel() == "D change [%]")
    # the change at which a check turns no-go: short of r2 = +600 %
    assert any(line.get_label() == "no-go change" and 450.0 < line.get_ydata()[0] < 600.0
               for line in d.get_lines())
    assert FORECAST_LABEL not in [t.get_text() for leg in stable.legends
                                  for t in leg.get_texts()]


def test_a_friction_panel_does_not_draw_falls_beyond_minus_100_percent() -> None:
    """r2 = +600 % drew the panel down to -690 %: half of it for changes a
    positive friction cannot make. Its lower limit now follows the data."""
    import matplotlib.pyplot as plt

    from condmon.report.figures import trend_figure
    from condmon.report.trends import TrendData

    def panel(change: list[float], r2: float) -> Any:
        c = np.array(change)
        d = TrendData("D", tuple(range(len(c))), np.arange(len(c)), "test", c,
                      np.full(len(c), 20.0), np.full(len(c), 2.0), np.zeros(len(c)),
                      np.zeros(len(c)), ("go",) * len(c), 15.0, r2 / 2, r2, 2.0)
        fig = trend_figure([d])
        lims = fig.axes[0].get_ylim()
        plt.close(fig)
        return lims

    assert panel([5.0, 40.0, 250.0], 600.0) == pytest.approx((-110.0, 690.0))
    assert panel([5.0, -95.0, 250.0], 600.0)[0] == pytest.approx(-1.1 * 115.0)
    assert panel([5.0, 40.0], 60.0) == pytest.approx((-69.0, 69.0))   # below 100 %: symmetric


def test_a_unit_at_no_go_has_no_forecast_in_its_legend() -> None:
    """The legend named a forecast band and a continued trend that a unit at
    no-go already has no room to draw; the no-go line alone is drawn."""
    import matplotlib.pyplot as plt

    from condmon.report.figures import trend_figure
    from condmon.report.trends import FORECAST_LABEL, ForecastBand, TrendData

    c = np.array([100.0, 300.0, 550.0])
    d = TrendData("D", (1, 2, 3), np.arange(3), "test", c, np.full(3, 20.0), np.full(3, 2.0),
                  np.zeros(3), np.zeros(3), ("go", "advisory", "no-go"), 15.0, 300.0, 600.0, 2.0)
    for ahead, shown in ((np.linspace(0.0, 1e-9, 40), False), (np.linspace(0.0, 3.0, 40), True)):
        band = ForecastBand("D", "tests", (1, 2, 3), ahead, np.full(40, 560.0),
                            np.full(40, 540.0), np.full(40, 580.0), 513.0)
        fig = trend_figure([d], [band])
        labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
        plt.close(fig)
        assert "no-go change" in labels and (FORECAST_LABEL in labels) is shown


def test_a_path_forecast_is_drawn_as_its_numbers_say() -> None:
    """A path forecast recalibrated on its fleet (its lives came early): the
    drawn median reaches the no-go line at the forecast's median, and the band's
    edges at its interval's ends (the coefficients' band went the other way, up
    from -16 % at 14 cycles left)."""
    from condmon.forecast.calibration import MIN_PEERS, calibrate
    from condmon.forecast.measured import forecast_path
    from condmon.forecast.unit import ParameterForecast
    from condmon.report.trends import forecast_band

    x = np.arange(1.0, 61.0)
    y = -0.3 * x + 0.5 * np.sin(x / 3.0)
    c = calibrate(np.linspace(0.0, 0.2, 41), MIN_PEERS)
    f = forecast_path(x, y, np.zeros(60), 0.5, -30.0, calibration=c)
    assert f.remaining is not None
    med, low, high = f.remaining
    band = forecast_band(ParameterForecast("capacity", "Ah", "-30 %", f,
                                           test_ids=tuple(range(1, 61))), "tests", points=401)
    assert band is not None
    def at(line: np.ndarray, r: float) -> float:
        return float(line[int(np.argmin(np.abs(band.ahead - r)))])

    step = float(band.ahead[1] - band.ahead[0])
    assert at(band.median, med) == pytest.approx(-30.0, abs=step)
    assert at(band.low, low) == pytest.approx(-30.0, abs=step)   # falling: the soonest lowest
    assert at(band.median, 0.0) == pytest.approx(at(band.high, 0.0))
    assert np.all(band.low <= band.median) and np.all(band.median <= band.high)
