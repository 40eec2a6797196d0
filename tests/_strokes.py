"""Synthetic records of a hydraulic rotary actuator, written as the test stand
writes its files (a sample counter, 14-bit counts, the node's own columns), with
known friction: for the tests and the routine-records benchmark."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
DECLARATION = ROOT / "examples" / "hydraulic-actuator" / "rotary-actuator.toml"


def _one_stroke_copy() -> Path:
    """The example's files with a test of one stroke (its ``cycle`` line left
    out), in a folder of this process's own, removed at exit."""
    import atexit
    import shutil
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="condmon-stroke-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    for f in DECLARATION.parent.glob("*.toml"):
        text = f.read_text()
        if f.name == DECLARATION.name:
            assert 'cycle = ["forward", "reverse"]\n' in text
            text = text.replace('cycle = ["forward", "reverse"]\n', "")
        (folder / f.name).write_text(text)
    return folder / DECLARATION.name


#: The example declaration with a test of one stroke, not a cycle: each record
#: is a test, its regimes (``Tc@forward``) with baselines of their own.
STROKE_DECLARATION = _one_stroke_copy()

#: The declaration's scales: rad and Pa per count, and the displacement [m^3/rad].
ANGLE_SCALE = 2 * math.pi / 16384
PRESSURE_SCALE = 1262.54
DM = 8.2e-5

#: Friction of the synthetic actuator: Coulomb [N m], viscous [N m s/rad], load [N m].
TRUTH = {"Tc": 40.0, "Dv": 5.0, "Tl": 2.0}


def stroke(speed: float, *, seed: int = 0, fs: float = 250.0, n: int = 3000,
           stroke_s: float = 1.6, start: int = 12, friction: dict[str, float] | None = None,
           hold_only: bool = False, noise_counts: float = 3.0, vibration: float = 20.0,
           oil: float = 12200.0) -> pd.DataFrame:
    """One record: a stroke at ``speed`` [rad/s] (its sign the direction) from
    sample ``start`` for ``stroke_s`` seconds, then a hold against the end stop.

    The driving pressure difference balances the friction during the stroke,
    ``Dm Δp = Dv ω + Tc sign ω + Tl``; in the hold the stop takes a large
    torque. Columns as the stand writes them: ``Time`` (1..n), ``Angle``,
    ``PG_1``, ``PG_2``, ``Accel_1..3`` (about 8,192 counts, ``vibration``
    counts of white noise during the stroke, a tenth of it in the hold),
    ``Temp_1..3`` (``oil`` counts) and the node's ``F_Names``, ``F_Values``,
    ``Prediction``.
    """
    f = {**TRUTH, **(friction or {})}
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    moving = (np.arange(n) >= start) & (np.arange(n) < start + int(stroke_s * fs))
    if hold_only:
        moving[:] = False
    omega = np.where(moving, speed, 0.0)
    theta = 1.0 + np.cumsum(omega) / fs
    dp = np.where(moving, (f["Dv"] * speed + f["Tc"] * np.sign(speed) + f["Tl"]) / DM,
                  np.sign(speed) * 7.0e6)
    base = 4.2e6
    pa, pb = base + dp / 2, base - dp / 2
    counts = {"Angle": theta / ANGLE_SCALE, "PG_1": pa / PRESSURE_SCALE,
              "PG_2": pb / PRESSURE_SCALE}
    df = pd.DataFrame({"Time": np.arange(1, n + 1)})
    for name, value in counts.items():
        df[name] = np.round(value + noise_counts * rng.standard_normal(n)).astype(int)
    shake = np.where(moving, vibration, vibration / 10.0)
    for k in (1, 2, 3):
        df[f"Accel_{k}"] = np.round(8192.0 + shake * rng.standard_normal(n)).astype(int)
        df[f"Temp_{k}"] = np.round(oil + rng.standard_normal(n)).astype(int)
    df["F_Names"] = [f"feature {i % 7}" for i in range(n)]
    df["F_Values"] = rng.standard_normal(n)
    df["Prediction"] = 0.0
    return df


def write_stroke(path: Path, speed: float, **kw: object) -> Path:
    """:func:`stroke` written as the stand does (tab-separated ``.txt``)."""
    stroke(speed, **kw).to_csv(path, sep="\t", index=False)  # type: ignore[arg-type]
    return path
