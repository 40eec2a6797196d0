"""Figures of one isolation (like the reference paper's Figs. 19–25): the
normalised residuals with their ±1 thresholds, and each suspect model's output
error against the measurements."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402

from condmon.diagnose.isolation import IsolationResult  # noqa: E402
from condmon.diagnose.residuals import moving_average  # noqa: E402
from condmon.models.declared import PlantModel  # noqa: E402

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
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.3 * n + 0.6), sharex=True, squeeze=False)
    for j, ax in enumerate(axes[:, 0]):
        ax.axhspan(-1, 1, color="#d5f5e3", lw=0, label="normal band")
        ax.plot(r.t, d.normalised[:, j], color="#1f4e79", lw=0.8)
        ax.axhline(1, color="#27ae60", lw=0.8)
        ax.axhline(-1, color="#27ae60", lw=0.8)
        _mark(ax, res)
        fired = " (fired)" if r.names[j] in d.fired else ""
        ax.set_ylabel(f"{r.names[j]}{fired}\n[z·σ]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper left", fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"{res.model}: normalised residuals ({res.normalisation.source})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_model_errors(res: IsolationResult, model: PlantModel, measured: np.ndarray,
                      path: Path) -> Path:
    """Each suspect model's output error, in units of the sensor's noise."""
    t = res.residuals.t
    sensors = model.sensors
    fig, axes = plt.subplots(len(sensors), 1, figsize=(9, 2.6 * len(sensors) + 0.6),
                             sharex=True, squeeze=False)
    noise = res.sensor_noise
    n_avg = max(1, int(round(res.normalisation.window / float(t[1] - t[0]))))
    colors = plt.get_cmap("tab10")
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
    axes[0, 0].legend(loc="upper left", fontsize=7, ncol=3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"{res.model}: output error of each suspect's model — {res.statement}",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_isolation_figures(res: IsolationResult, model: PlantModel, measured: np.ndarray,
                            out_dir: Path) -> list[Path]:
    """Write ``residuals.png`` and, after a detection, ``model-errors.png``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = [plot_residuals(res, out_dir / "residuals.png")]
    if res.outputs:
        files.append(plot_model_errors(res, model, measured, out_dir / "model-errors.png"))
    return files
