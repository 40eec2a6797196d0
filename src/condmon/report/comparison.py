"""The measured-against-model figure of ``condmon validate``.

One panel per output: the measured signal and the simulated one on the same
axes, and below it the simulation error, with the RMSE and fit % in the title.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from condmon.errors import DataError
from condmon.report.figures import legend_below, new_figure, save_figure
from condmon.simulate.compare import Comparison

__all__ = ["plot_comparison"]


def plot_comparison(c: Comparison, path: str | Path | None = None) -> Any:
    """Draw (and with ``path``, write as PNG) measured against model.

    Parameters
    ----------
    c : Comparison
    path : str or Path, optional

    Returns
    -------
    matplotlib.figure.Figure

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> from condmon.io.records import validate_record
    >>> from condmon.simulate.compare import compare_model, initial_states
    >>> m = get_model("dc-motor")
    >>> rec = validate_record(simulate_plant(m.plant, seed=1), ("V", "I", "omega"))
    >>> fig = plot_comparison(compare_model(rec, m, {}, initial_states(m, rec, "first-sample")))
    >>> len(fig.axes)
    4
    """
    if c.measured is None:
        raise DataError(f"{c.source}: no measured outputs to draw the model against")
    n = len(c.outputs)
    fig = new_figure(8.0, 2.6 * n + 0.6)
    grid = fig.add_gridspec(2 * n, 1, height_ratios=[3, 1] * n)
    for j, name in enumerate(c.outputs):
        ax = fig.add_subplot(grid[2 * j])
        unit = c.units.get(name, "")
        ax.plot(c.t, c.measured[:, j], color="black", lw=0.8, label="measured")
        ax.plot(c.t, c.simulated[:, j], color="tab:red", lw=0.9, label="model (simulated)")
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        ax.set_title(f"{c.source}: {name}, RMSE {c.rmse[name]:.4g} {unit}, "
                     f"fit {c.fit_percent[name]:.1f} %", fontsize=9)
        ax.tick_params(labelbottom=False)
        err = fig.add_subplot(grid[2 * j + 1], sharex=ax)
        err.plot(c.t, c.measured[:, j] - c.simulated[:, j], color="tab:gray", lw=0.7)
        err.axhline(0.0, color="black", lw=0.5)
        err.set_ylabel(f"error [{unit}]" if unit else "error", fontsize=8)
        if j == n - 1:
            err.set_xlabel("time from the record's start [s]")
        else:
            err.tick_params(labelbottom=False)
    legend_below(fig, fig.axes[0].get_legend_handles_labels(), 2)
    if path is not None:
        save_figure(fig, str(path))
    return fig
