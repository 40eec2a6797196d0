"""Figures of a unit's history (like the reference paper's Figs. 4-6).

Every figure numbers tests by their id in the history (``#12``) and, when the
tests carry dates, puts them on a time axis. The trend figure draws what a
check's status depends on: the r1/r2 bands, the baseline's own spread (±k·σ),
and for each test the symptom half-width ±k·max(σ, SE) around its change; each
point is coloured by the status stored for it, so the picture and the table
agree. Excluded and rejected tests are never trended.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, TypeVar

import numpy as np
import pandas as pd

from condmon.monitor.fuzzy import MonitorConfig

__all__ = ["plot_trends", "plot_fits", "plot_symptoms", "plot_isolation_trends",
           "trend_data", "TrendData", "STATUS_COLOURS"]

#: Colour of each status in every figure and page.
STATUS_COLOURS = {"go": "#2e7d32", "advisory": "#ef6c00", "no-go": "#c62828",
                  "retest": "#546e7a", "baseline": "#7f8c8d", "rejected": "#c0392b",
                  "excluded": "#bdbdbd", "unchecked": "#9e9e9e"}

Target = TypeVar("Target", str, Path, IO[bytes])


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    return plt


def _x(rows: pd.DataFrame, dated: bool) -> tuple[Any, str]:
    """The x values of ``rows``: dates when the history has test dates, else test ids."""
    if dated:
        return rows["date"].dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(), "test date (UTC)"
    return np.asarray(rows.index, dtype=float), "test # (no test dates recorded)"


def _dated(history: pd.DataFrame) -> bool:
    return "test_date" in history and bool(history["test_date"].notna().any())


@dataclass(frozen=True)
class TrendData:
    """What the trend figure draws for one parameter (in percent of the baseline mean).

    Attributes
    ----------
    test_ids : tuple of int
        The checks drawn (accepted, not excluded), in history order.
    change : ndarray
        Change against the baseline. [%]
    width : ndarray
        Symptom half-width ``k·max(σ_baseline, SE)/|mean|·100``. [%]
    se : ndarray
        Each estimate's standard error. [%]
    status : tuple of str
        The status stored for each test.
    spread : float
        ``k·σ_baseline/|mean|·100``, the baseline's own band. [%]
    """

    test_ids: tuple[int, ...]
    change: np.ndarray[Any, np.dtype[np.float64]]
    width: np.ndarray[Any, np.dtype[np.float64]]
    se: np.ndarray[Any, np.dtype[np.float64]]
    status: tuple[str, ...]
    spread: float


def _checked(history: pd.DataFrame) -> pd.DataFrame:
    """Accepted, not excluded checks with an evaluation: what trends."""
    ok = (history["role"] == "check") & history["accepted"].astype(bool)
    if "excluded" in history:
        ok &= ~history["excluded"].astype(bool)
    return history[ok]


def trend_data(history: pd.DataFrame, parameter: str, mean: float, std: float,
               k: float) -> TrendData:
    """The numbers :func:`plot_trends` draws for ``parameter``.

    Parameters
    ----------
    history : DataFrame
        :meth:`HistoryStore.history` of the unit.
    parameter : str
    mean, std : float
        The baseline's mean and standard deviation of the parameter. [its unit]
    k : float
        Symptom width in standard deviations (the monitor's ``k``).

    Example
    -------
    >>> h = pd.DataFrame({"role": ["check"], "accepted": [True], "excluded": [False],
    ...                   "status": ["go"], "R_change": [5.0], "R_se": [0.01]}, index=[7])
    >>> d = trend_data(h, "R", 1.0, 0.02, 2.0)
    >>> d.test_ids, float(d.width[0]), d.spread
    ((7,), 4.0, 4.0)
    """
    chk = _checked(history)
    scale = 100.0 / abs(mean) if mean else np.nan
    change = (chk[f"{parameter}_change"].to_numpy(dtype=float) if f"{parameter}_change" in chk
              else np.full(len(chk), np.nan))
    se = (chk[f"{parameter}_se"].to_numpy(dtype=float) * scale if f"{parameter}_se" in chk
          else np.full(len(chk), np.nan))
    width = k * np.fmax(std * scale, np.nan_to_num(se, nan=0.0))
    return TrendData(tuple(int(i) for i in chk.index), change, width, se,
                     tuple(str(s) for s in chk["status"]), float(k * std * scale))


def _bands(ax: Any, r1: float, r2: float, top: float, steps: int = 6) -> None:
    """r1..r2 shaded darker towards r2 (the HIGH/LOW degree rises from 0 to 1
    across it), beyond r2 the fault band."""
    edges = np.linspace(r1, r2, steps + 1)
    for i in range(steps):
        alpha = 0.1 + 0.5 * (i + 0.5) / steps
        label = "developing (r1..r2; degree 0 to 1)" if i == steps - 1 else None
        ax.axhspan(edges[i], edges[i + 1], color="#f6b93b", alpha=alpha, lw=0, label=label)
        ax.axhspan(-edges[i + 1], -edges[i], color="#f6b93b", alpha=alpha, lw=0)
    ax.axhspan(r2, top, color="#f28b82", alpha=0.55, lw=0, label="fault (> r2)")
    ax.axhspan(-top, -r2, color="#f28b82", alpha=0.55, lw=0)


def plot_trends(history: pd.DataFrame, parameters: Sequence[str], cfg: MonitorConfig,
                path: Target, baseline: Any = None) -> Target:
    """Percent change of each parameter over the checks, against time or test id.

    ``baseline`` (a :class:`~condmon.monitor.Baseline`) gives the spread band
    and the symptom widths; without it only the changes and the r1/r2 bands
    are drawn.
    """
    plt = _pyplot()
    chk = _checked(history)
    dated = _dated(history)
    x, xlabel = _x(chk, dated)
    n = len(parameters)
    fig, axes = plt.subplots((n + 1) // 2, 2, figsize=(10, 2.6 * ((n + 1) // 2)),
                             sharex=True, squeeze=False)
    stats = {} if baseline is None else {
        p: (m, s) for p, m, s in zip(baseline.parameters, baseline.mean, baseline.std)}
    for ax, p in zip(axes.ravel(), parameters):
        r1, r2 = cfg.r1[p], cfg.r2[p]
        m, s = stats.get(p, (1.0, 0.0))
        d = trend_data(history, p, m, s if p in stats else 0.0, cfg.k)
        reach = np.abs(d.change) + (d.width if p in stats else 0)
        top = max(r2 * 1.15, float(np.nanmax(reach)) * 1.1 if np.isfinite(reach).any() else 0)
        _bands(ax, r1, r2, top)
        if p in stats:
            ax.axhspan(-d.spread, d.spread, color="#90caf9", alpha=0.5, lw=0,
                       label=f"baseline ±{cfg.k:g}σ")
        ax.axhline(0, color="0.5", lw=0.8)
        if len(chk):
            ax.plot(x, d.change, "-", color="0.6", lw=0.8, zorder=2)
            for status in dict.fromkeys(d.status):
                sel = np.array([st == status for st in d.status])
                ax.errorbar(x[sel], d.change[sel], yerr=d.width[sel] if p in stats else None,
                            fmt="o", ms=4, color=STATUS_COLOURS.get(status, "k"), capsize=2,
                            lw=0.8, zorder=3, label=status)
        ax.set_ylim(-top, top)
        ax.set_ylabel(f"{p} change [%]")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    for ax in axes[-1]:
        ax.set_xlabel(xlabel)
    if dated:
        fig.autofmt_xdate()
    elif len(chk):
        for ax in axes.ravel()[:n]:
            ax.set_xticks(x)
            ax.set_xticklabels([f"#{i}" for i in chk.index], fontsize=7)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    axes[0, 0].legend(seen.values(), seen.keys(), loc="upper left", fontsize=6, ncol=2)
    fig.suptitle("Change against the healthy baseline; bars: symptom width "
                 f"±{cfg.k:g}·max(σ baseline, SE)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_fits(history: pd.DataFrame, threshold: float, path: Target) -> Target:
    """Percentage fit of every test (excluded ones greyed), with the threshold."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 2.8))
    dated = _dated(history)
    x, xlabel = _x(history, dated)
    fit = history["fit_percent"].to_numpy(dtype=float)
    status = history["status"].astype(str).to_numpy()
    ax.axhline(threshold, color="#c0392b", ls="--", lw=1, label=f"threshold {threshold:g} %")
    for st in dict.fromkeys(status):
        sel = status == st
        ax.plot(x[sel], np.nan_to_num(fit[sel], nan=0.0),
                "x" if st in ("rejected", "retest") else "o", ms=5,
                color=STATUS_COLOURS.get(st, "k"), label=st)
    ax.set_xlabel(xlabel)
    if not dated and len(history):
        ax.set_xticks(x)
        ax.set_xticklabels([f"#{i}" for i in history.index], fontsize=7)
    ax.set_ylabel("fit [%]")
    lo = float(np.nanmin(fit)) - 2 if np.isfinite(fit).any() else 80.0
    ax.set_ylim(min(80.0, lo), 100.5)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left", ncol=4)
    ax.set_title("Model fit per test (R_T², mean over outputs)")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_symptoms(history: pd.DataFrame, parameters: Sequence[str], path: Target) -> Target:
    """SymH (up) and SymL (down) of each parameter for every trended check."""
    plt = _pyplot()
    chk = _checked(history)
    fig, ax = plt.subplots(figsize=(10, 3.2))
    n, m = len(chk), len(parameters)
    width = 0.8 / max(m, 1)
    colors = plt.get_cmap("tab10")
    for j, p in enumerate(parameters):
        xs = np.arange(n) + (j - (m - 1) / 2) * width
        hi = chk[f"{p}_high"].to_numpy(dtype=float) if f"{p}_high" in chk else np.zeros(n)
        lo = chk[f"{p}_low"].to_numpy(dtype=float) if f"{p}_low" in chk else np.zeros(n)
        ax.bar(xs, np.nan_to_num(hi), width, color=colors(j), label=p)
        ax.bar(xs, -np.nan_to_num(lo), width, color=colors(j), alpha=0.5)
    ax.axhline(0, color="0.3", lw=0.8)
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel("test #")
    ax.set_ylabel("SymL (down) / SymH (up)")
    ax.set_xticks(np.arange(n))
    ax.set_xticklabels([f"#{i}" for i in chk.index], fontsize=7)
    ax.legend(ncol=max(m, 1), fontsize=7, loc="lower left")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title("Fuzzy symptoms per check")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_isolation_trends(isolations: pd.DataFrame, path: Target) -> Target:
    """Each suspect's estimated change in every isolation of a unit (bars per
    isolation, the isolated suspect outlined; rejected estimates left out)."""
    plt = _pyplot()
    iso = isolations[~isolations["excluded"].astype(bool)] if len(isolations) else isolations
    params = sorted(c[:-len("_change")] for c in iso.columns if c.endswith("_change"))
    fig, ax = plt.subplots(figsize=(10, 3.2))
    n, m = len(iso), len(params)
    width = 0.8 / max(m, 1)
    colors = plt.get_cmap("tab10")
    biggest = 0.0
    for j, p in enumerate(params):
        y = iso[f"{p}_change"].to_numpy(dtype=float)
        if f"{p}_rejected" in iso:
            y = np.where(iso[f"{p}_rejected"].fillna(False).astype(bool), np.nan, y)
        isolated = np.array([p in list(v) for v in iso["isolated"]], dtype=bool)
        xs = np.arange(n) + (j - (m - 1) / 2) * width
        ax.bar(xs, np.nan_to_num(y), width, color=colors(j % 10), label=p,
               edgecolor=np.where(isolated, "black", "none").tolist(), linewidth=1.5)
        if np.isfinite(y).any():
            biggest = max(biggest, float(np.nanmax(np.abs(y))))
    if biggest > 200:
        ax.set_yscale("symlog", linthresh=50)
    ax.axhline(0, color="0.3", lw=0.8)
    ax.set_xticks(np.arange(n))
    ax.set_xticklabels([f"i{i}\n{d:%Y-%m-%d}\n{s}" for i, d, s in
                        zip(iso.index, iso["date"], iso["status"])], fontsize=7)
    ax.set_ylabel("estimate change [%]")
    ax.grid(alpha=0.3, axis="y")
    if params:
        ax.legend(fontsize=7, ncol=min(m, 8), loc="upper left")
    ax.set_title("Suspects' steady-state estimates against nominal (outlined: isolated)")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
    return path
