"""EMPS by the benchmark's own simulation method: the closed loop simulated.

The EMPS record (Janot, Gautier, Brunot 2019) is a closed-loop position test.
Its authors identify it by DIDIM (Gautier, Janot, Vandanjon 2013, IEEE TCST
21): the axis is simulated *with its controller*, driven by the recorded
reference ``qg``, and the parameters are those whose simulated controller
output matches the recorded one, ``vir``. This is a reference computation for
``bench_simulation.py``, beside condmon's two routes, so that the gap between
them can be read against the method the published values come from.

The controller is the record's own, sampled at 1 kHz: ``vir = kv (kp (qg − qm)
− (qm − qm_prev)/Ts)`` (velocity by backward difference), held over each
sample; between samples the axis ``M q'' = gtau vir − Fv q' − Fc sign(q') −
offset`` is integrated by fourth-order Runge-Kutta. Simulated this way with the
published parameters it reproduces the recorded ``vir`` to 0.079 V RMS.

Written here by hand: a declaration is continuous-time, so condmon cannot yet
simulate a sampled controller; no library fits this loop either.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
from scipy.optimize import least_squares

NAMES = ("M", "Fv", "Fc", "offset")


def _simulate(p: np.ndarray, rec: dict[str, Any]) -> np.ndarray:
    """The controller output [V] of the simulated closed loop, per sample."""
    m, fv, fc, off = (float(v) for v in p)
    qg, ts, kp, kv, gtau = rec["qg"], rec["ts"], rec["kp"], rec["kv"], rec["gtau"]
    q = q_prev = float(rec["qm"][0])
    qd = 0.0
    out = np.empty(qg.size)

    def acc(force: float, v: float) -> float:
        coulomb = math.copysign(fc, v) if v != 0.0 else 0.0
        return (force - fv * v - coulomb - off) / m

    for k in range(qg.size):   # a sampled loop: one step per sample, state by state
        u = kv * (kp * (qg[k] - q) - (q - q_prev) / ts)
        out[k] = u
        q_prev = q
        f = gtau * u
        a1 = acc(f, qd)
        a2 = acc(f, qd + 0.5 * ts * a1)
        a3 = acc(f, qd + 0.5 * ts * a2)
        a4 = acc(f, qd + ts * a3)
        q += ts / 6.0 * (qd + 2.0 * (qd + 0.5 * ts * a1) + 2.0 * (qd + 0.5 * ts * a2)
                         + (qd + ts * a3))
        qd += ts / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return out


def closed_loop_fit(mat: Path, start: dict[str, float]) -> dict[str, Any]:
    """Fit M, Fv, Fc and offset by the closed loop's controller-output error.

    Standard errors two ways: the white-noise bound ``s² (JᵀJ)⁻¹`` and the
    batch-means (cluster-robust) sandwich over 20 contiguous blocks, the
    definition condmon's simulation route uses. [parameter units]
    """
    m = scipy.io.loadmat(str(mat))
    t = m["t"].ravel().astype(np.float64)
    rec = {"qg": m["qg"].ravel().astype(np.float64), "qm": m["qm"].ravel().astype(np.float64),
           "ts": float(np.median(np.diff(t))), "kp": float(m["kp"].item()),
           "kv": float(m["kv"].item()), "gtau": float(m["gtau"].item())}
    vir = m["vir"].ravel().astype(np.float64)
    x0 = np.array([start[k] for k in NAMES], dtype=np.float64)
    fit = least_squares(lambda p: _simulate(p, rec) - vir, x0,
                        x_scale=np.maximum(np.abs(x0) * 0.01, 1e-3), diff_step=1e-4)
    jac, e = fit.jac, fit.fun
    n, k = e.size, x0.size
    a_inv = np.linalg.inv(jac.T @ jac)
    white = a_inv * float(e @ e) / (n - k)
    edges = np.linspace(0, n, 21).round().astype(int)
    g = np.array([(jac[a:b] * e[a:b, None]).sum(axis=0) for a, b in zip(edges[:-1], edges[1:])])
    robust = a_inv @ (g.T @ g * (20 / 19)) @ a_inv
    se = np.maximum(np.sqrt(np.diag(white)), np.sqrt(np.diag(robust)))
    return {"parameters": dict(zip(NAMES, map(float, fit.x))),
            "std_errors": dict(zip(NAMES, map(float, se))),
            "white_std_errors": dict(zip(NAMES, map(float, np.sqrt(np.diag(white))))),
            "vir_rms": float(np.sqrt(np.mean(e ** 2))),
            "simulations": int(fit.nfev) + int(fit.njev or 0) * k}
