"""Figures of a unit's history (like the reference paper's Figs. 4-6)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from condmon.monitor.fuzzy import MonitorConfig  # noqa: E402

__all__ = ["plot_trends", "plot_fits", "plot_symptoms"]


def _checked(history: pd.DataFrame) -> pd.DataFrame:
    return history[(history["role"] == "check") & history["accepted"].astype(bool)]


def plot_trends(history: pd.DataFrame, parameters: list[str], cfg: MonitorConfig,
                path: Path) -> Path:
    """Percent change of each parameter over the checked tests, with r1/r2 bands."""
    chk = _checked(history)
    n = len(parameters)
    fig, axes = plt.subplots((n + 1) // 2, 2, figsize=(10, 2.4 * ((n + 1) // 2)),
                             sharex=True, squeeze=False)
    x = np.arange(1, len(chk) + 1)
    for ax, p in zip(axes.ravel(), parameters):
        r1, r2 = cfg.r1[p], cfg.r2[p]
        y = chk[f"{p}_change"].to_numpy(dtype=float) if f"{p}_change" in chk else np.full(len(chk), np.nan)
        top = max(r2 * 1.15, float(np.nanmax(np.abs(y))) * 1.1 if y.size and np.isfinite(y).any() else 0)
        ax.axhspan(r1, r2, color="#f6d365", alpha=0.45, lw=0, label="developing (r1..r2)")
        ax.axhspan(r2, top, color="#f28b82", alpha=0.45, lw=0, label="fault (> r2)")
        ax.axhspan(-r2, -r1, color="#f6d365", alpha=0.45, lw=0)
        ax.axhspan(-top, -r2, color="#f28b82", alpha=0.45, lw=0)
        ax.axhline(0, color="0.5", lw=0.8)
        ax.plot(x, y, "o-", color="#1f4e79", ms=4)
        ax.set_ylim(-top, top)
        ax.set_ylabel(f"{p} change [%]")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("checked test")
    axes[0, 0].legend(loc="upper left", fontsize=7)
    fig.suptitle("Parameter change against the healthy baseline")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_fits(history: pd.DataFrame, threshold: float, path: Path) -> Path:
    """Percentage fit of every test, accepted and rejected, with the threshold."""
    fig, ax = plt.subplots(figsize=(10, 2.8))
    x = np.arange(1, len(history) + 1)
    fit = history["fit_percent"].to_numpy(dtype=float)
    acc = history["accepted"].astype(bool).to_numpy()
    base = (history["role"] == "baseline").to_numpy()
    ax.axhline(threshold, color="#c0392b", ls="--", lw=1, label=f"threshold {threshold:g} %")
    ax.plot(x[acc & base], fit[acc & base], "s", color="#7f8c8d", label="baseline test")
    ax.plot(x[acc & ~base], fit[acc & ~base], "o", color="#1f4e79", label="checked test")
    ax.plot(x[~acc], np.nan_to_num(fit[~acc], nan=0.0), "x", color="#c0392b", ms=8,
            label="rejected")
    ax.set_xlabel("test (in order)")
    ax.set_ylabel("fit [%]")
    ax.set_ylim(min(80.0, float(np.nanmin(fit)) - 2 if np.isfinite(fit).any() else 80.0), 100.5)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left", ncol=4)
    ax.set_title("Model fit per test (R_T², mean over outputs)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_symptoms(history: pd.DataFrame, parameters: list[str], path: Path) -> Path:
    """SymH (up) and SymL (down) of each parameter for every checked test."""
    chk = _checked(history)
    fig, ax = plt.subplots(figsize=(10, 3.2))
    n, m = len(chk), len(parameters)
    width = 0.8 / max(m, 1)
    colors = plt.get_cmap("tab10")
    for j, p in enumerate(parameters):
        xs = np.arange(1, n + 1) + (j - (m - 1) / 2) * width
        hi = chk[f"{p}_high"].to_numpy(dtype=float) if f"{p}_high" in chk else np.zeros(n)
        lo = chk[f"{p}_low"].to_numpy(dtype=float) if f"{p}_low" in chk else np.zeros(n)
        ax.bar(xs, hi, width, color=colors(j), label=p)
        ax.bar(xs, -lo, width, color=colors(j), alpha=0.5)
    ax.axhline(0, color="0.3", lw=0.8)
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel("checked test")
    ax.set_ylabel("SymL (down) / SymH (up)")
    ax.set_xticks(np.arange(1, n + 1))
    ax.legend(ncol=m, fontsize=7, loc="lower left")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title("Fuzzy symptoms per checked test")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
