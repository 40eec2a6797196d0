"""Figures of one isolation (like the reference paper's Figs. 19–25): the
normalised residuals with their ±1 thresholds, and each suspect model's output
error against the measurements. Legends sit below the axes, never on a curve
(:func:`condmon.report.figures.legend_below`)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes

from condmon.diagnose.isolation import IsolationResult
from condmon.diagnose.residuals import moving_average
from condmon.models.declared import PlantModel
from condmon.report.figures import legend_below, new_figure, save_figure

__all__ = ["plot_residuals", "plot_model_errors", "write_isolation_figures"]


def _mark(ax: Axes, res: IsolationResult) -> None:
    if res.detection_time is not None:
        ax.axvline(res.detection_time, color="#c0392b", lw=1.0, ls="--", label="detection")
    if res.compare_from is not None:
        ax.axvline(res.compare_from, color="0.4", lw=0.8, ls=":", label="comparison from")


def plot_residuals(res: IsolationResult, path: Path) -> Path:
    """Normalised residuals with the ±1 thresholds and the detection time."""
    r, d = res.residuals, res.detection
    n = len(r.names)
    fig = new_figure(9, 2.3 * n + 1.0)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)
    for j, ax in enumerate(axes[:, 0]):
        ax.axhspan(-1, 1, color="#d5f5e3", lw=0, label="normal band")
        ax.plot(r.t, d.normalised[:, j], color="#1f4e79", lw=0.8)
        ax.axhline(1, color="#27ae60", lw=0.8)
        ax.axhline(-1, color="#27ae60", lw=0.8)
        _mark(ax, res)
        fired = " (fired)" if r.names[j] in d.fired else ""
        ax.set_ylabel(f"{r.names[j]}{fired}\n[z·σ]")
        ax.grid(alpha=0.3)
    legend_below(fig, axes[0, 0].get_legend_handles_labels(), ncol=3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"{res.model}: normalised residuals ({res.normalisation.source})")
    return save_figure(fig, path)


def plot_model_errors(res: IsolationResult, model: PlantModel, measured: np.ndarray,
                      path: Path) -> Path:
    """Each suspect model's output error, in units of the sensor's noise."""
    t = res.residuals.t
    sensors = model.sensors
    fig = new_figure(9, 2.6 * len(sensors) + 1.2)
    axes = fig.subplots(len(sensors), 1, sharex=True, squeeze=False)
    noise = res.sensor_noise
    n_avg = max(1, int(round(res.normalisation.window / float(t[1] - t[0]))))
    colors = colormaps["tab10"]
    order = sorted(res.outputs, key=lambda p: p in res.isolated)  # isolated drawn on top
    for k, (ax, s) in enumerate(zip(axes[:, 0], sensors)):
        for p in order:
            i = list(res.outputs).index(p)
            err = moving_average(((measured[:, k] - res.outputs[p][:, k]) / noise[k])[:, None],
                                 n_avg)[:, 0]
            top = p in res.isolated
            ax.plot(t, err, "-" if top else "--", lw=1.4 if top else 0.9, color=colors(i % 10),
                    label=f"{p} (RMS {res.errors.get(p, float('nan')):.2f})")
        _mark(ax, res)
        ax.set_ylabel(f"{s.name} error\n[noise σ, {res.normalisation.window:g} s mean]")
        ax.grid(alpha=0.3)
        lim = 10 * max(1.0, min((res.errors[p] for p in res.isolated), default=1.0))
        ax.set_ylim(-lim, lim)
    legend_below(fig, axes[0, 0].get_legend_handles_labels(), ncol=4)
    axes[-1, 0].set_xlabel("time [s]")
    # a statement runs to several clauses: wrapped to the figure's width, not cut off
    fig.suptitle(textwrap.fill(f"{res.model}: output error of each suspect's model — "
                               f"{res.statement}", 130), fontsize=10)
    return save_figure(fig, path)


def write_isolation_figures(res: IsolationResult, model: PlantModel, measured: np.ndarray,
                            out_dir: Path) -> list[Path]:
    """Write ``residuals.png`` and, after a detection, ``model-errors.png``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = [plot_residuals(res, out_dir / "residuals.png")]
    if res.outputs:
        files.append(plot_model_errors(res, model, measured, out_dir / "model-errors.png"))
    return files
