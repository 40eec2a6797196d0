"""Figures of a unit's history (like the reference paper's Figs. 4-6).

Each figure draws one of the results of :mod:`condmon.report.trends`, so its
content can be checked without pixels. Tests are numbered by their id in the
history (``#12``) everywhere and, when the tests carry dates, placed on a time
axis. The trend figure draws what a check's status depends on: the r1/r2
bands, the active baseline's spread (±k·σ) around 0, and for each check the
symptom half-width ±k·max(σ, SE) of its evaluation as its error bar (the one
error bar of every figure and page, :func:`condmon.report.trends.error_bar`); each point
is coloured by the status stored for it and filled when this parameter's
symptom is above 0, so the picture agrees with the table. Excluded tests are
never drawn; rejected ones only in the fit figure.

matplotlib is imported when a figure is drawn (Agg back-end, files only).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:
    from condmon.report.trends import FitData, IsolationTrend, TrendData

__all__ = ["plot_trends", "plot_fits", "plot_symptoms", "plot_isolation_trends",
           "STATUS_COLOURS"]

#: Colour of each status in every figure and page.
STATUS_COLOURS = {"go": "#2e7d32", "advisory": "#ef6c00", "no-go": "#c62828",
                  "retest": "#546e7a", "baseline": "#7f8c8d", "rejected": "#c0392b",
                  "excluded": "#bdbdbd", "unchecked": "#9e9e9e", "building": "#90a4ae"}

Target = TypeVar("Target", str, Path, IO[bytes])


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    return plt


def _dated(x: np.ndarray[Any, Any]) -> bool:
    return np.issubdtype(x.dtype, np.datetime64)


def _label_tests(axes: Sequence[Any], x: np.ndarray[Any, Any], ids: Sequence[int],
                 y: Sequence[np.ndarray[Any, Any]] | None = None, prefix: str = "#") -> None:
    """Number the points by id: as tick labels on an id axis, next to each
    point (``y`` per axis) on a date axis."""
    if not len(ids):
        return
    if not _dated(x):
        for ax in axes:
            ax.set_xticks(x)
            ax.set_xticklabels([f"{prefix}{i}" for i in ids], fontsize=7)
        return
    for ax, yy in zip(axes, y or []):
        for xi, yi, i in zip(x, yy, ids):
            if np.isfinite(yi):
                ax.annotate(f"{prefix}{i}", (xi, yi), xytext=(3, 3),
                            textcoords="offset points", fontsize=6, color="0.25")


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


def _finish(plt: Any, fig: Any, path: Target) -> Target:
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_trends(trends: Sequence[TrendData], path: Target) -> Target:
    """Percent change of each parameter over the trended checks.

    Parameters
    ----------
    trends : sequence of TrendData
        One per parameter (:func:`condmon.report.trends.trend_data`), same tests.
    path : str, Path or binary file
        Where the PNG goes.

    Returns
    -------
    The ``path`` given.
    """
    from matplotlib.lines import Line2D

    from condmon.report.trends import error_bar

    plt = _pyplot()
    n = max(len(trends), 1)
    rows = (n + 1) // 2
    fig, axes = plt.subplots(rows, 2, figsize=(10, 2.6 * rows + 0.4), sharex=True,
                             squeeze=False)
    statuses: dict[str, None] = {}
    for ax, d in zip(axes.ravel(), trends):
        reach = np.abs(d.change) + np.nan_to_num(d.width)
        top = max(d.r2 * 1.15, float(np.nanmax(reach)) * 1.1 if np.isfinite(reach).any() else 0)
        _bands(ax, d.r1, d.r2, top)
        if np.isfinite(d.spread):
            ax.axhspan(-d.spread, d.spread, color="#90caf9", alpha=0.5, lw=0,
                       label=f"baseline ±{d.k:g}σ")
        ax.axhline(0, color="0.5", lw=0.8)
        ax.plot(d.x, d.change, "-", color="0.6", lw=0.8, zorder=2)
        filled = d.reaches_r1
        for status in dict.fromkeys(d.status):
            statuses[status] = None
            sel = np.array([s == status for s in d.status], dtype=bool)
            colour = STATUS_COLOURS.get(status, "k")
            ax.errorbar(d.x[sel], d.change[sel], yerr=np.nan_to_num(d.width[sel]), fmt="none",
                        ecolor=colour, capsize=2, lw=0.8, zorder=3)
            for fill in (True, False):
                pick = sel & (filled == fill)
                if pick.any():
                    ax.plot(d.x[pick], d.change[pick], "o", ms=5, mec=colour,
                            mfc=colour if fill else "white", zorder=4)
        ax.set_ylim(-top, top)
        ax.set_ylabel(f"{d.parameter} change [%]")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(trends):]:
        ax.axis("off")
    if trends:
        _label_tests(axes.ravel()[:len(trends)], trends[0].x, trends[0].test_ids,
                     [d.change for d in trends])
        for ax in axes[-1]:
            ax.set_xlabel(trends[0].xlabel)
        if _dated(trends[0].x):
            fig.autofmt_xdate()
        handles, labels = axes[0, 0].get_legend_handles_labels()
        seen = dict(zip(labels, handles))
        for status in statuses:
            seen[status] = Line2D([], [], ls="", marker="o", color=STATUS_COLOURS.get(status, "k"))
        seen["filled: this symptom > 0"] = Line2D([], [], ls="", marker="o", color="0.3")
        seen["open: this symptom = 0"] = Line2D([], [], ls="", marker="o", mec="0.3", mfc="white")
        axes[0, 0].legend(seen.values(), seen.keys(), loc="upper left", fontsize=6, ncol=2)
    k = trends[0].k if trends else float("nan")
    fig.suptitle(f"Change against the healthy baseline; error bars: {error_bar(k)} (symptom "
                 "half-width, σ: baseline std, SE: standard error); excluded and rejected "
                 "tests not drawn", fontsize=9)
    return _finish(plt, fig, path)


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
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 2.8))
    ax.axhline(threshold, color="#c0392b", ls="--", lw=1, label=f"threshold {threshold:g} %")
    status = np.asarray(data.status, dtype=object)
    for st in dict.fromkeys(data.status):
        sel = status == st
        ax.plot(data.x[sel], data.fit[sel], "x" if st in ("rejected", "retest") else "o",
                ms=5, color=STATUS_COLOURS.get(st, "k"), label=st)
    _label_tests([ax], data.x, data.test_ids, [data.fit])
    ax.set_xlabel(data.xlabel)
    if _dated(data.x):
        fig.autofmt_xdate()
    ax.set_ylabel("fit [%]")
    lo = float(np.nanmin(data.fit)) - 2 if np.isfinite(data.fit).any() else 80.0
    ax.set_ylim(min(80.0, lo), 100.5)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left", ncol=4)
    ax.set_title("Model fit per test (R_T², mean over outputs; excluded tests not drawn)",
                 fontsize=10)
    return _finish(plt, fig, path)


def plot_symptoms(trends: Sequence[TrendData], path: Target) -> Target:
    """SymH (up) and SymL (down) of each parameter for every trended check.

    Parameters
    ----------
    trends : sequence of TrendData
    path : str, Path or binary file

    Returns
    -------
    The ``path`` given.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ids = trends[0].test_ids if trends else ()
    n, m = len(ids), len(trends)
    width = 0.8 / max(m, 1)
    colors = plt.get_cmap("tab10")
    for j, d in enumerate(trends):
        xs = np.arange(n) + (j - (m - 1) / 2) * width
        ax.bar(xs, np.nan_to_num(d.high), width, color=colors(j % 10), label=d.parameter)
        ax.bar(xs, -np.nan_to_num(d.low), width, color=colors(j % 10), alpha=0.5)
    ax.axhline(0, color="0.3", lw=0.8)
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel("test # (in the order of the trend figure)")
    ax.set_ylabel("SymL (down) / SymH (up)")
    ax.set_xticks(np.arange(n))
    ax.set_xticklabels([f"#{i}" for i in ids], fontsize=7)
    if m:
        ax.legend(ncol=m, fontsize=7, loc="lower left")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title("Fuzzy symptoms per check", fontsize=10)
    return _finish(plt, fig, path)


def plot_isolation_trends(data: IsolationTrend, path: Target) -> Target:
    """Each suspect's estimated change over the isolations of a unit.

    Points of one suspect are joined; the suspect an isolation named is drawn
    large with a black edge. Every isolation is marked on the zero line in
    the colour of its status (also one that estimated nothing). Estimates
    rejected from the comparison and excluded isolations are not drawn.

    Parameters
    ----------
    data : IsolationTrend
    path : str, Path or binary file

    Returns
    -------
    The ``path`` given.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.4))
    colors = plt.get_cmap("tab10")
    biggest, named = 0.0, False
    for j, (p, y) in enumerate(data.change.items()):
        colour = colors(j % 10)
        shown = bool(np.isfinite(y).any())
        ax.plot(data.x, y, "-o", ms=4, lw=1.0, color=colour,
                label=p if shown else f"{p} (rejected or not estimated)")
        hit = data.isolated[p] & np.isfinite(y)
        if hit.any():
            named = True
            ax.plot(data.x[hit], y[hit], "o", ms=10, mfc=colour, mec="black", mew=1.8, zorder=4)
        if shown:
            biggest = max(biggest, float(np.nanmax(np.abs(y))))
    if biggest > 200:
        ax.set_yscale("symlog", linthresh=50)
    ax.axhline(0, color="0.3", lw=0.8)
    status = np.asarray(data.status, dtype=object)
    for st in dict.fromkeys(data.status):  # every isolation on the zero line, by status
        sel = status == st
        ax.plot(data.x[sel], np.zeros(int(sel.sum())), "s", ms=6, mec="0.2",
                color=STATUS_COLOURS.get(st, "k"), label=f"isolation: {st}", zorder=3)
    _label_tests([ax], data.x, data.isolation_ids, [np.zeros(len(data.x))], prefix="i")
    if _dated(data.x):
        fig.autofmt_xdate()
    ax.set_xlabel(data.xlabel)
    ax.set_ylabel("estimate change [%]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=8, loc="upper left")
    ax.set_title("Suspects' steady-state estimates against nominal"
                 + (" (large, black edge: isolated)" if named else ""), fontsize=10)
    return _finish(plt, fig, path)
