"""Figures of a unit's history (like the reference paper's Figs. 4-6).

Each figure draws one of the results of :mod:`condmon.report.trends`, so its
content can be checked without pixels. Tests are numbered by their id in the
history (``#12``) everywhere and, when the tests carry dates, placed on a time
axis. The trend figure draws what a check's status depends on: the r1/r2
bands, the active baseline's spread (±k·σ) around 0, and for each check the
symptom half-width ±k·max(σ, SE) of its evaluation as its error bar (the one
error bar of every figure and page, :func:`condmon.report.trends.error_bar`); each point
is coloured by the status stored for it (green, go, on a panel whose own
symptom is 0: another parameter made the check advisory or no-go) and filled
when this parameter's
symptom is above 0, so the picture agrees with the table; a parameter trending
towards no-go gets its forecast: the fitted trend continued from the last check
to the no-go change (dotted: where a check turns no-go, short of r2) with its
90 % band shaded. Excluded tests are
never drawn; rejected ones only in the fit figure.

Every legend sits outside the axes (below them), so it never covers a point;
every axis includes every value it draws; a symptom figure has a panel per
parameter with each test's bar on its tick.

matplotlib is imported when a figure is drawn. Figures are built as
:class:`matplotlib.figure.Figure` objects with their own Agg canvas, never
through pyplot's global state, so pages may draw them in several threads at
once (the fleet page does).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:
    from condmon.report.trends import FitData, ForecastBand, IsolationTrend, TrendData

__all__ = ["plot_trends", "plot_fits", "plot_symptoms", "plot_isolation_trends",
           "trend_figure", "fit_figure", "symptom_figure", "isolation_figure", "new_figure",
           "legend_below", "save_figure", "STATUS_COLOURS"]

#: Colour of each status in every figure and page.
STATUS_COLOURS = {"go": "#2e7d32", "advisory": "#ef6c00", "no-go": "#c62828",
                  "retest": "#546e7a", "baseline": "#7f8c8d", "rejected": "#c0392b",
                  "excluded": "#bdbdbd", "unchecked": "#9e9e9e", "building": "#90a4ae",
                  "stale": "#6d4c41"}

Target = TypeVar("Target", str, Path, IO[bytes])

#: Resolution of every PNG figure. [dots per inch]
DPI = 110

#: Space kept between the outermost value and the axis limit. [fraction of the axis]
_MARGIN = 0.08


def new_figure(width: float, height: float) -> Any:
    """An empty figure with its own Agg canvas and constrained layout.

    Parameters
    ----------
    width, height : float
        Size. [in]

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _slant_dates(fig: Any) -> None:
    """Date labels of the x axis slanted (matplotlib's ``autofmt_xdate``). The
    constrained layout makes their room; matplotlib 3.8 would warn that it cannot
    also move the axes, as it then leaves them where they are (later versions
    skip the move without a word)."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "This figure was using a layout engine",
                                UserWarning)
        fig.autofmt_xdate()


def legend_below(fig: Any, entries: tuple[Sequence[Any], Sequence[str]], ncol: int,
                 fontsize: float = 7) -> Any:
    """The figure's legend below every axes (the layout makes room for it),
    where it cannot cover any value; None without entries.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    entries : (handles, labels)
        As ``Axes.get_legend_handles_labels`` returns them.
    ncol : int
        Most entries in a row.
    fontsize : float
        [pt]
    """
    handles, labels = entries
    if not handles:
        return None
    return fig.legend(list(handles), list(labels), loc="outside lower center",
                      ncol=max(1, min(ncol, len(handles))), fontsize=fontsize, frameon=False)


def save_figure(fig: Any, path: Target) -> Target:
    """Write ``fig`` as PNG to ``path`` (a file name or a binary file); returns ``path``."""
    fig.savefig(path, dpi=DPI, format="png")
    return path


def _dated(x: np.ndarray[Any, Any]) -> bool:
    return np.issubdtype(x.dtype, np.datetime64)


def _ordinal(n: int) -> str:
    """``2nd``, ``3rd``, ``11th``, ``21st``.

    Example
    -------
    >>> [_ordinal(n) for n in (1, 2, 3, 4, 11, 12, 13, 21, 22)]
    ['1st', '2nd', '3rd', '4th', '11th', '12th', '13th', '21st', '22nd']
    """
    tail = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{tail}"


def _label_tests(axes: Sequence[Any], x: np.ndarray[Any, Any], ids: Sequence[int],
                 y: Sequence[np.ndarray[Any, Any]] | None = None, prefix: str = "#") -> None:
    """Number the points by id: as tick labels on an id axis, next to each
    point (``y`` per axis) on a date axis."""
    if not len(ids):
        return
    every = _label_every(axes[0], x, max(len(f"{prefix}{i}") for i in ids),
                         7.0 if not _dated(x) else 6.0)
    if not _dated(x):
        from matplotlib.ticker import FuncFormatter, MaxNLocator

        for ax in axes:
            if every == 1:
                ax.set_xticks(x)
                ax.set_xticklabels([f"{prefix}{i}" for i in ids], fontsize=7)
                continue
            # an id axis: whole ids at a readable spacing, not one per test
            span = float(np.ptp(x)) or 1.0
            ax.xaxis.set_major_locator(MaxNLocator(nbins=max(2, int(len(x) / every)),
                                                   integer=True, min_n_ticks=2))
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{prefix}{v:.0f}"))
            ax.tick_params(axis="x", labelsize=7)
            # (a forecast drawn past the last check keeps its room)
            ax.set_xlim(float(np.min(x)) - 0.02 * span,
                        max(float(np.max(x)) + 0.02 * span, float(ax.get_xlim()[1])))
        return
    for ax, yy in zip(axes, y or []):
        for k, (xi, yi, i) in enumerate(zip(x, yy, ids)):
            if np.isfinite(yi) and k % every == 0:
                ax.annotate(f"{prefix}{i}", (xi, yi), xytext=(3, 3),
                            textcoords="offset points", fontsize=6, color="0.25")


def _label_every(ax: Any, x: np.ndarray[Any, Any], chars: int, fontsize: float) -> int:
    """Label one point in this many so that labels of ``chars`` characters
    never touch: the axes' width over the points' spacing, with a character
    about 0.6 of the font size wide and one character of gap."""
    n = len(x)
    if n < 2:
        return 1
    fig = ax.get_figure()
    width_in = fig.get_size_inches()[0] * ax.get_position().width * 0.9
    # the points may fill only part of the axis (a forecast drawn beyond them)
    if _dated(x):
        from matplotlib.dates import date2num

        xs = np.asarray(date2num(x.astype("datetime64[ms]").astype(object)),  # type: ignore[no-untyped-call]
                        dtype=np.float64)
    else:
        xs = np.asarray(x, dtype=np.float64)
    lo, hi = ax.get_xlim()
    if hi > lo and np.ptp(xs) > 0:
        width_in *= min(1.0, float(np.ptp(xs)) / (hi - lo))
    label_in = (chars + 2) * 0.65 * fontsize / 72.0
    room = max(1, int(width_in / label_in))
    return 1 if n <= room else int(np.ceil(n / room))


def _bands(ax: Any, r1: float, r2: float, top: float, steps: int = 6) -> None:
    """r1..r2 shaded darker towards r2 (the HIGH/LOW degree rises from 0 to 1
    across it), beyond r2 the fault band; inside ±r1 left white (normal)."""
    edges = np.linspace(r1, r2, steps + 1)
    for i in range(steps):
        alpha = 0.1 + 0.5 * (i + 0.5) / steps
        label = "developing: r1..r2 (symptom 0 to 1)" if i == steps - 1 else None
        ax.axhspan(edges[i], edges[i + 1], color="#f6b93b", alpha=alpha, lw=0, label=label)
        ax.axhspan(-edges[i + 1], -edges[i], color="#f6b93b", alpha=alpha, lw=0)
    ax.axhspan(r2, top, color="#f28b82", alpha=0.55, lw=0, label="fault: beyond r2")
    ax.axhspan(-top, -r2, color="#f28b82", alpha=0.55, lw=0)


def _grid(n: int, row_height: float, title_height: float = 0.9) -> tuple[Any, Any]:
    """A figure of ``n`` panels in two columns sharing x (one panel: the
    whole width); the unused one is switched off and the panel above it shows
    the x tick labels."""
    rows = (max(n, 1) + 1) // 2
    fig = new_figure(10, row_height * rows + title_height)
    axes = fig.subplots(rows, 2 if n > 1 else 1, sharex=True, squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    if n % 2 and rows > 1:
        axes[-2, 1].tick_params(labelbottom=True)
    return fig, axes


def _bottom_axes(axes: Any, n: int) -> list[Any]:
    """The lowest used panel of each column (where the x label goes)."""
    flat = list(axes.ravel()[:n])
    return [flat[j] for j in sorted({max(i for i in range(len(flat)) if i % 2 == c)
                                     for c in range(min(2, len(flat)))})]


def _forecast(ax: Any, d: TrendData, band: ForecastBand) -> set[str]:
    """The fitted trend continued from the last check to the no-go line, its
    90 % band shaded, and the no-go line; what was drawn (``band``, ``line``).
    A unit at no-go already has no future to draw: the line alone."""
    from condmon.report.trends import FORECAST_LABEL

    where = {i: j for j, i in enumerate(d.test_ids)}
    at = [where[i] for i in band.test_ids if i in where]
    dated = _dated(d.x)
    if len(at) < 2 or (band.by == "days" and not dated):
        return set()
    x = d.x[at].astype("datetime64[ns]").astype(np.int64).astype(np.float64) if dated \
        else np.asarray(d.x[at], dtype=np.float64)
    ahead = band.x(x, 86400e9)
    drawn = {"line"}
    # a future to draw: the band's reach beyond a thousandth of the checks' span (at
    # no-go already it is nil; a minutes-long history forecast in days still has one)
    if float(np.ptp(ahead)) > 1e-3 * float(np.ptp(x)):
        xs = ahead.astype(np.int64).astype("datetime64[ns]") if dated else ahead
        ax.fill_between(xs, band.low, band.high, color="#7e57c2", alpha=0.4, lw=0,
                        label=FORECAST_LABEL, zorder=1)
        ax.plot(xs, band.median, "--", color="#5e35b1", lw=1.0, zorder=2,
                label="forecast: the fitted trend continued")
        drawn.add("band")
    ax.axhline(band.threshold, color="#b71c1c", ls=":", lw=1.2, zorder=2, label="no-go change")
    return drawn


def _bottom(d: TrendData, top: float) -> float:
    """The panel's lower limit: ``-top``, but not far below -100 % unless a
    check's bar goes there. A fall of more than 100 % turns a positive
    quantity's sign, so a no-go band at -600 % (a friction's r2) would take
    half the panel for changes that cannot happen."""
    low = np.nanmax(np.nan_to_num(d.width) - d.change, initial=0.0) if len(d.change) else 0.0
    return -top if d.r2 < 100.0 else -min(top, max(110.0, 1.1 * float(low)))


def trend_figure(trends: Sequence[TrendData], bands: Sequence[ForecastBand] = ()) -> Any:
    """The trend figure of :func:`plot_trends` (a matplotlib ``Figure``)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from condmon.report.trends import FORECAST_LABEL, USAGE_LABELS, error_bar

    n = len(trends)
    fig, axes = _grid(n, 2.4, 1.4)
    statuses: dict[str, None] = {}
    ahead = {b.parameter: b for b in bands}
    forecast: set[str] = set()
    for ax, d in zip(axes.ravel(), trends):
        if d.parameter in ahead:
            forecast |= _forecast(ax, d, ahead[d.parameter])
        reach = np.abs(d.change) + np.nan_to_num(d.width)
        top = max(d.r2 * 1.15, float(np.nanmax(reach)) * 1.1 if np.isfinite(reach).any() else 0)
        _bands(ax, d.r1, d.r2, top)
        if np.isfinite(d.spread):
            ax.axhspan(-d.spread, d.spread, color="#90caf9", alpha=0.5, lw=0,
                       label=f"baseline ±{d.k:g}σ")
        ax.axhline(0, color="0.5", lw=0.8)
        ax.plot(d.x, d.change, "-", color="0.6", lw=0.8, zorder=2)
        filled = d.reaches_r1
        shown = d.panel_status   # coloured by this parameter's own symptom
        for status in dict.fromkeys(shown):
            statuses[status] = None
            sel = np.array([s == status for s in shown], dtype=bool)
            colour = STATUS_COLOURS.get(status, "k")
            ax.errorbar(d.x[sel], d.change[sel], yerr=np.nan_to_num(d.width[sel]), fmt="none",
                        ecolor=colour, capsize=2, lw=0.8, zorder=3)
            for fill in (True, False):
                pick = sel & (filled == fill)
                if pick.any():
                    ax.plot(d.x[pick], d.change[pick], "o", ms=5, mec=colour,
                            mfc=colour if fill else "white", zorder=4)
        ax.set_ylim(_bottom(d, top), top)
        ax.set_ylabel(f"{d.parameter} change [%]")
        ax.grid(alpha=0.3)
    k = trends[0].k if trends else float("nan")
    if trends:
        if trends[0].xlabel not in USAGE_LABELS:   # (on a usage axis, its own numbers)
            _label_tests(axes.ravel()[:n], trends[0].x, trends[0].test_ids,
                         [d.change for d in trends])
        for ax in _bottom_axes(axes, n):
            ax.set_xlabel(trends[0].xlabel)
        if _dated(trends[0].x):
            _slant_dates(fig)
        handles, labels = axes[0, 0].get_legend_handles_labels()
        seen = dict(zip(labels, handles))
        for status in statuses:
            seen[status] = Line2D([], [], ls="", marker="o", color=STATUS_COLOURS.get(status, "k"))
        seen[f"error bar {error_bar(k)}"] = Line2D([], [], ls="-", color="0.3", lw=0.8)
        seen["filled: this symptom > 0"] = Line2D([], [], ls="", marker="o", color="0.3")
        seen["open: this symptom = 0"] = Line2D([], [], ls="", marker="o", mec="0.3", mfc="white")
        if "band" in forecast:  # whichever panel drew it
            seen[FORECAST_LABEL] = Patch(color="#7e57c2", alpha=0.4, lw=0)
            seen["forecast: the fitted trend continued"] = Line2D([], [], ls="--",
                                                                  color="#5e35b1", lw=1.0)
        if "line" in forecast:
            seen["no-go change"] = Line2D([], [], ls=":", color="#b71c1c", lw=1.2)
        legend_below(fig, (list(seen.values()), list(seen)), ncol=5)
    fig.suptitle("Change against the healthy baseline (checks only: baseline, excluded and "
                 f"rejected tests not drawn)\nerror bars: {error_bar(k)}, the symptom "
                 "half-width (σ: baseline "
                 "std, SE: the estimate's standard error)", fontsize=9)
    return fig


def plot_trends(trends: Sequence[TrendData], path: Target,
                bands: Sequence[ForecastBand] = ()) -> Target:
    """Percent change of each parameter over the trended checks.

    Parameters
    ----------
    trends : sequence of TrendData
        One per parameter (:func:`condmon.report.trends.trend_data`), same tests.
    path : str, Path or binary file
        Where the PNG goes.
    bands : sequence of ForecastBand
        Forecasts to no-go (:func:`condmon.report.trends.forecast_band`): on
        its parameter's panel, the fitted trend continued from the last check
        with its 90 % band shaded ("forecast, 90 % interval") and the no-go
        line.

    Returns
    -------
    The ``path`` given.
    """
    return save_figure(trend_figure(trends, bands), path)


def fit_figure(data: FitData, threshold: float) -> Any:
    """The fit figure of :func:`plot_fits` (a matplotlib ``Figure``)."""
    from condmon.report.trends import USAGE_LABELS

    fig = new_figure(10, 3.2)
    ax = fig.subplots()
    ax.axhline(threshold, color="#c0392b", ls="--", lw=1, label=f"threshold {threshold:g} %")
    status = np.asarray(data.status, dtype=object)
    for st in dict.fromkeys(data.status):
        sel = status == st
        ax.plot(data.x[sel], data.fit[sel], "x" if st in ("rejected", "retest") else "o",
                ms=5, color=STATUS_COLOURS.get(st, "k"), label=st)
    if data.xlabel not in USAGE_LABELS:
        _label_tests([ax], data.x, data.test_ids, [data.fit])
    ax.set_xlabel(data.xlabel)
    if _dated(data.x):
        _slant_dates(fig)
    ax.set_ylabel("fit [%]")
    finite = data.fit[np.isfinite(data.fit)]
    lo = min(80.0, threshold, float(finite.min()) if finite.size else 80.0)
    hi = max(100.0, float(finite.max()) if finite.size else 100.0)
    ax.set_ylim(lo - _MARGIN * (hi - lo), hi + _MARGIN * (hi - lo))
    ax.grid(alpha=0.3)
    legend_below(fig, ax.get_legend_handles_labels(), ncol=8)
    ax.set_title("Model fit per test (R_T², mean over outputs; excluded tests not drawn)",
                 fontsize=10)
    return fig


def plot_fits(data: FitData, threshold: float, path: Target) -> Target:
    """Percentage fit of every test that is not excluded, with the threshold.

    Parameters
    ----------
    data : FitData
    threshold : float
        Fit below which a test is rejected. [%]
    path : str, Path or binary file

    Returns
    -------
    The ``path`` given.
    """
    return save_figure(fit_figure(data, threshold), path)


def symptom_figure(trends: Sequence[TrendData]) -> Any:
    """The symptom figure of :func:`plot_symptoms` (a matplotlib ``Figure``)."""
    from matplotlib.patches import Patch

    n = len(trends)
    fig, axes = _grid(n, 1.7)
    ids = trends[0].test_ids if trends else ()
    at = np.arange(len(ids), dtype=np.float64)
    # labels that do not overlap: at most 12 across a panel (half the figure's width)
    every = max(1, int(np.ceil(len(ids) / 12)))
    ticks = at[::every]   # a tick only where there is a label: ticks cost the figure's time
    labels = [f"#{i}" for i in list(ids)[::every]]
    for ax, d in zip(axes.ravel(), trends):
        ax.bar(at, np.nan_to_num(d.high), 0.6, color="#ef6c00", align="center")
        ax.bar(at, -np.nan_to_num(d.low), 0.6, color="#1565c0", align="center")
        ax.axhline(0, color="0.3", lw=0.8)
        ax.set_ylim(-1.05, 1.05)
        ax.set_yticks([-1.0, 0.0, 1.0])
        ax.set_ylabel(f"{d.parameter} symptom [-]")
        ax.set_xticks(ticks)
        ax.set_xticklabels(labels, fontsize=7)
        ax.set_xlim(-0.6, len(ids) - 0.4)
        ax.grid(alpha=0.3, axis="y")
    for ax in _bottom_axes(axes, n):
        ax.set_xlabel("test # (in the order of the trend figure)")
    legend_below(fig, ([Patch(color="#ef6c00"), Patch(color="#1565c0")],
                       ["SymH (up): degree of HIGH", "SymL (down): degree of LOW"]), ncol=2)
    fig.suptitle("Fuzzy symptoms per check and parameter (one pair of bars a test, in "
                 "order" + (")" if every == 1 else f"; every {_ordinal(every)} labelled)"), fontsize=10)
    return fig


def plot_symptoms(trends: Sequence[TrendData], path: Target) -> Target:
    """SymH (up) and SymL (down) of each parameter for every trended check.

    One panel per parameter; each test's bars in the trend figure's order,
    at most 12 of them labelled with their test's number.

    Parameters
    ----------
    trends : sequence of TrendData
    path : str, Path or binary file

    Returns
    -------
    The ``path`` given.
    """
    return save_figure(symptom_figure(trends), path)


def _include(ax: Any, values: np.ndarray[Any, Any], margin: float = _MARGIN) -> None:
    """Set the y limits so that every finite value (and 0) lies inside, with
    ``margin`` of the axis to spare, in the axis's own scale (linear or symlog)."""
    v = np.append(values[np.isfinite(values)], 0.0)
    scale = ax.yaxis.get_transform()
    lo, hi = (float(t) for t in scale.transform(np.array([v.min(), v.max()])))
    pad = margin * (hi - lo) if hi > lo else 1.0
    low, high = (float(t) for t in scale.inverted().transform(np.array([lo - pad, hi + pad])))
    ax.set_ylim(low, high)


def isolation_figure(data: IsolationTrend) -> Any:
    """The isolation figure of :func:`plot_isolation_trends` (a matplotlib ``Figure``)."""
    from matplotlib import colormaps
    from matplotlib.ticker import FuncFormatter

    fig = new_figure(10, 3.8)
    ax = fig.subplots()
    colors = colormaps["tab10"]
    named = False
    drawn = [y[np.isfinite(y)] for y in data.change.values()]
    values = np.concatenate(drawn) if drawn else np.zeros(0)
    symlog = bool(values.size) and float(np.max(np.abs(values))) > 200
    if symlog:  # linear within ±100 %, logarithmic beyond
        ax.set_yscale("symlog", linthresh=100)
    for j, (p, y) in enumerate(data.change.items()):
        colour = colors(j % 10)
        why = data.unshown.get(p)
        ax.plot(data.x, y, "-o", ms=4, lw=1.0, color=colour,
                label=p if why is None else f"{p} ({why})")
        hit = data.isolated[p] & np.isfinite(y)
        if hit.any():
            named = True
            ax.plot(data.x[hit], y[hit], "o", ms=10, mfc=colour, mec="black", mew=1.8, zorder=4)
            last = data.x[-1]
            for xi, yi in zip(data.x[hit], y[hit]):  # the isolated estimate's number
                left = bool(xi == last) and len(data.x) > 1  # inwards at the right edge
                ax.annotate(f"{p} {yi:+.1f} %", (xi, yi), xytext=(-9 if left else 9, -3),
                            textcoords="offset points", ha="right" if left else "left",
                            fontsize=7, color="0.15")
    ax.axhline(0, color="0.3", lw=0.8)
    status = np.asarray(data.status, dtype=object)
    for st in dict.fromkeys(data.status):  # every isolation on the zero line, by status
        sel = status == st
        ax.plot(data.x[sel], np.zeros(int(sel.sum())), "s", ms=6, mec="0.2",
                color=STATUS_COLOURS.get(st, "k"), label=f"isolation: {st}", zorder=3)
    _include(ax, values)
    if symlog:
        low, high = ax.get_ylim()
        decades = np.log10(max(abs(low), abs(high), 100.0) / 100.0)
        steps = [m * 10.0 ** e for e in range(2, 40) for m in ((1, 2, 5) if decades < 2 else (1,))]
        ticks = sorted({t for v in (0, 50, *steps) for t in (v, -v) if low <= t <= high})
        ax.set_yticks(ticks)
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:+g}" if v else "0"))
    _label_tests([ax], data.x, data.isolation_ids, [np.zeros(len(data.x))], prefix="i")
    if _dated(data.x):
        _slant_dates(fig)
    ax.set_xlabel(data.xlabel)
    ax.set_ylabel("estimate change [%]")
    ax.grid(alpha=0.3)
    legend_below(fig, ax.get_legend_handles_labels(), ncol=6)
    ax.set_title("Suspects' steady-state estimates against nominal"
                 + (" (large, black edge: isolated)" if named else ""), fontsize=10)
    return fig


def plot_isolation_trends(data: IsolationTrend, path: Target) -> Target:
    """Each suspect's estimated change over the isolations of a unit.

    Points of one suspect are joined; the suspect an isolation named is drawn
    large with a black edge. Every isolation is marked on the zero line in
    the colour of its status (also one that estimated nothing). Estimates
    rejected from the comparison and excluded isolations are not drawn; a
    suspect without a drawn point says why in the legend. The axis holds
    every estimate (symmetric-log beyond ±200 %).

    Parameters
    ----------
    data : IsolationTrend
    path : str, Path or binary file

    Returns
    -------
    The ``path`` given.
    """
    return save_figure(isolation_figure(data), path)
