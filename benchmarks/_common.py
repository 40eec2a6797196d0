"""Helpers shared by the benchmark scripts: result files and plain-text tables.

Every benchmark says the machine's load beside its figures: the 1-minute load
average when this module is imported (the script's start) is printed then, and
:func:`write_json` prints the load at the end and writes both into the result.
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import lfilter

RESULTS = Path(__file__).parent / "results"
LOAD_AT_START = os.getloadavg()[0]
print(f"load average (1 min) at the start: {LOAD_AT_START:.2f} on {os.cpu_count()} cores",
      flush=True)


def write_json(name: str, doc: dict[str, Any]) -> Path:
    """Write ``results/<name>.json`` with a small provenance header."""
    RESULTS.mkdir(exist_ok=True)
    end = os.getloadavg()[0]
    print(f"load average (1 min) at the end: {end:.2f} on {os.cpu_count()} cores")
    doc = {"benchmark": name, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
           "python": platform.python_version(), "machine": platform.machine(),
           "cores": os.cpu_count(), "loadavg_1min_start": LOAD_AT_START,
           "loadavg_1min_end": end, **doc}
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(doc, indent=2, allow_nan=True))
    return path


def best_of(fn: Any, repeat: int) -> float:
    """The shortest of ``repeat`` timed calls of ``fn()``. [s]"""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def table(rows: list[dict[str, Any]], title: str) -> str:
    """Fixed-width text table of a list of dicts (same keys)."""
    keys = list(rows[0])

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(r[k]) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[i]) for c in cells)) for i, k in enumerate(keys)]
    line = "  ".join(k.rjust(w) for k, w in zip(keys, widths))
    out = [title, line, "-" * len(line)]
    out += ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in cells]
    return "\n".join(out)


def oe_information(theta: np.ndarray, u: np.ndarray, sigma: np.ndarray, n: int = 2) -> np.ndarray:
    """Fisher information of the common-denominator output-error model.

    ``Σ_j (1/σ_j²) Σ_k ψ_j ψ_jᵀ`` with ψ_j the gradient of the noise-free output
    ``B_j/A u`` with respect to ``θ = [a, b_1, ..., b_m]`` (white output noise).
    """
    m = sigma.size
    a = np.r_[1.0, theta[:n]]
    x = lfilter([1.0], a, u)
    uf = lfilter([1.0], a, u)
    info = np.zeros((theta.size, theta.size))
    for j in range(m):
        b = np.r_[0.0, theta[n * (1 + j): n * (2 + j)]]
        yj = lfilter(b, [1.0], x)
        yf = lfilter([1.0], a, yj)
        psi = np.zeros((u.size, theta.size))
        for i in range(1, n + 1):
            psi[i:, i - 1] = -yf[:-i]
            psi[i:, n * (1 + j) + i - 1] = uf[:-i]
        info += psi.T @ psi / sigma[j] ** 2
    return info
