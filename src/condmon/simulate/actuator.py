"""Closed-loop electromechanical actuator test-bed (the built-in test, simulated).

A DC-equivalent brushless motor drives a ball-screw through a gearbox; a fixed
position controller (P position loop around a PI speed loop, plus a small current
feedback) closes the loop at the sample rate. Two band-limited white-noise
perturbations excite the rig: one on the position demand ``yd`` and one added to
the controller's voltage ``ud``. The drive holds the voltage over each sample
(zero-order hold); current and speed are measured with noise, and the *measured*
values are fed back, as on a real rig.

With the nonlinear effects off, the plant is propagated with its exact ZOH
discretisation, so the record satisfies the discrete model of the estimator
exactly (up to the measurement noise).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy import linalg, signal

from condmon._threads import one_blas_thread
from condmon.errors import ConfigError
from condmon.io.config import load_default, load_toml, merge
from condmon.simulate.faults import Fault, parse_fault

__all__ = ["ActuatorRig", "load_actuator_rig", "simulate_actuator", "band_limited_noise",
           "ar1_noise"]

FloatArray = NDArray[np.float64]

# Names a fault may change, and the TOML section each lives in.
_SECTIONS = ("motor", "drive", "controller", "test", "sensors", "nonlinear")


@dataclass(frozen=True)
class ActuatorRig:
    """Parameters of the simulated actuator rig (see ``condmon/data/actuator.toml``).

    Attributes
    ----------
    R : float
        Winding resistance. [ohm]
    L : float
        Winding inductance. [H]
    Kt : float
        Torque constant. [N m/A]
    gamma : float
        Ke / Kt. [-]
    J : float
        Inertia at the motor shaft. [kg m^2]
    D : float
        Viscous friction at the motor shaft. [N m s/rad]
    gear_ratio, screw_lead : float
        Motor turns per screw turn [-]; screw lead [m/rev].
    kp_position, kp_speed, ki_speed, k_current, v_max : float
        Controller gains [1/s], [V s/rad], [V/rad], [V/A] and voltage limit [V].
    duration, sample_rate : float
        Test length [s] and sample rate [Hz].
    yd_std, yd_bandwidth, ud_std, ud_bandwidth : float
        Perturbations: demand [m] and voltage [V] standard deviations, bandwidths [Hz].
    noise_I, noise_omega, current_quantisation : float
        Sensor noise standard deviations [A], [rad/s]; current resolution [A].
    noise_bandwidth : float
        Bandwidth of the sensor noise (anti-alias filtering) [Hz]; at or above
        Nyquist the noise is white.
    coulomb_friction, coulomb_smoothing : float
        Coulomb friction torque [N m]; smoothing speed [rad/s].
    saturation : bool
        Clip the drive voltage at ``v_max``.
    substeps : int
        Integration substeps per sample when Coulomb friction is on.
    """

    R: float
    L: float
    Kt: float
    gamma: float
    J: float
    D: float
    gear_ratio: float
    screw_lead: float
    kp_position: float
    kp_speed: float
    ki_speed: float
    k_current: float
    v_max: float
    duration: float
    sample_rate: float
    yd_std: float
    yd_bandwidth: float
    ud_std: float
    ud_bandwidth: float
    noise_I: float
    noise_omega: float
    noise_bandwidth: float
    current_quantisation: float
    coulomb_friction: float
    coulomb_smoothing: float
    saturation: bool
    substeps: int

    def __post_init__(self) -> None:
        for name in ("R", "L", "Kt", "gamma", "J", "sample_rate", "duration",
                     "screw_lead", "gear_ratio", "v_max"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"actuator parameter {name} must be positive, "
                                  f"got {getattr(self, name)}")
        for name in ("D", "noise_I", "noise_omega", "current_quantisation",
                     "coulomb_friction", "yd_std", "ud_std"):
            if getattr(self, name) < 0:
                raise ConfigError(f"actuator parameter {name} must be >= 0, "
                                  f"got {getattr(self, name)}")
        if self.substeps < 1:
            raise ConfigError(f"substeps must be >= 1, got {self.substeps}")

    @property
    def Ke(self) -> float:
        """Back-EMF constant ``gamma * Kt``. [V s/rad]"""
        return self.gamma * self.Kt

    @property
    def dt(self) -> float:
        """Sample time. [s]"""
        return 1.0 / self.sample_rate

    @property
    def metres_per_radian(self) -> float:
        """Nut travel per motor radian. [m/rad]"""
        return self.screw_lead / (2.0 * math.pi * self.gear_ratio)

    def physical(self) -> dict[str, float]:
        """The six monitored parameters ``R, L, Ke, Kt, J, D`` (SI units)."""
        return {"R": self.R, "L": self.L, "Ke": self.Ke, "Kt": self.Kt,
                "J": self.J, "D": self.D}

    def with_faults(self, faults: Iterable[str | Fault]) -> ActuatorRig:
        """A copy with parameter faults applied (``"R=+40%"``, ``"D=*7"``, ...).

        A fault on ``Kt`` moves ``Ke`` too (``gamma`` is a constant of the motor).
        """
        changes: dict[str, Any] = {}
        fields = {f.name: f for f in dataclasses.fields(self)}
        for item in faults:
            fault = parse_fault(item) if isinstance(item, str) else item
            if fault.name not in fields or fields[fault.name].type not in ("float", float):
                allowed = ", ".join(n for n, f in fields.items() if f.type in ("float", float))
                raise ConfigError(f"unknown actuator parameter {fault.name!r} in fault; "
                                  f"allowed: {allowed}")
            if fault.at is not None:
                raise ConfigError(f"fault {fault}: step times are not supported for the "
                                  "actuator test (a test is 4 s; use separate tests)")
            current = changes.get(fault.name, getattr(self, fault.name))
            if current == 0 and fault.kind in ("relative", "factor"):
                raise ConfigError(f"fault {fault}: {fault.name} is 0 on this rig (off), and a "
                                  f"change relative to 0 leaves it 0; give its value "
                                  f"({fault.name}=<value>) or a step (+<value>)")
            changes[fault.name] = fault.apply(current)
        return dataclasses.replace(self, **changes)


def load_actuator_rig(path: str | Path | None = None,
                      faults: Iterable[str | Fault] = ()) -> ActuatorRig:
    """Rig parameters from the shipped defaults, overridden by ``path`` if given.

    Example
    -------
    >>> rig = load_actuator_rig(faults=["R=+40%"])
    >>> round(rig.R, 3)
    1.4
    """
    cfg = load_default("actuator.toml")
    if path is not None:
        cfg = merge(cfg, load_toml(path), str(path))
    flat: dict[str, Any] = {}
    for section in _SECTIONS:
        flat.update(cfg[section])
    where = str(path) if path is not None else "actuator.toml"
    for k, v in flat.items():
        kind = bool if k == "saturation" else (int if k == "substeps" else float)
        if isinstance(v, str) or (kind is not bool and isinstance(v, bool)) \
                or not isinstance(v, (int, float, bool)):
            raise ConfigError(f"{where}: rig parameter {k!r} must be a "
                              f"{'true/false' if kind is bool else 'number'}, not {v!r}")
        flat[k] = kind(v)
    return ActuatorRig(**flat).with_faults(faults)


def band_limited_noise(n: int, std: float, bandwidth: float, sample_rate: float,
                       rng: np.random.Generator) -> FloatArray:
    """Gaussian white noise low-passed to ``bandwidth`` and scaled to ``std``.

    Parameters
    ----------
    n : int
        Number of samples.
    std : float
        Standard deviation of the result.
    bandwidth : float
        Cut-off of a 4th-order Butterworth filter [Hz]; at or above Nyquist the
        noise stays white (held over each sample).
    sample_rate : float
        [Hz]
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n,)
    """
    white = rng.standard_normal(n)  # drawn even for std 0, so seeds stay aligned
    if std == 0.0:
        return np.zeros(n)
    if bandwidth < 0.5 * sample_rate:
        sos = signal.butter(4, bandwidth, fs=sample_rate, output="sos")
        white = signal.sosfilt(sos, white)
    s = float(np.std(white))
    return white * (std / s) if s > 0 else white


def ar1_noise(n: int, std: float, phi: float, rng: np.random.Generator) -> FloatArray:
    """Gaussian AR(1) noise ``e[k] = phi e[k-1] + w[k]`` scaled to ``std``
    (coloured sensor noise for studies of the standard errors).

    Parameters
    ----------
    n : int
        Number of samples.
    std : float
        Standard deviation of the result (over these ``n`` samples).
    phi : float
        Lag-1 coefficient, ``-1 < phi < 1`` (0: white).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n,)

    Example
    -------
    >>> e = ar1_noise(5000, 0.1, 0.9, np.random.default_rng(0))
    >>> round(float(np.std(e)), 6), bool(np.corrcoef(e[1:], e[:-1])[0, 1] > 0.85)
    (0.1, True)
    """
    e = signal.lfilter([1.0], [1.0, -phi], rng.standard_normal(n))
    s = float(np.std(e))
    return np.asarray(e * (std / s) if s > 0 else e, dtype=np.float64)


def _zoh_matrices(rig: ActuatorRig, h: float) -> tuple[FloatArray, FloatArray]:
    """Exact ZOH propagation of [i, w, theta] over ``h`` with inputs [V, T_friction]."""
    A = np.array([[-rig.R / rig.L, -rig.Ke / rig.L, 0.0],
                  [rig.Kt / rig.J, -rig.D / rig.J, 0.0],
                  [0.0, 1.0, 0.0]])
    B = np.array([[1.0 / rig.L, 0.0], [0.0, -1.0 / rig.J], [0.0, 0.0]])
    M = np.zeros((5, 5))
    M[:3, :3] = A
    M[:3, 3:] = B
    E = linalg.expm(M * h)
    return E[:3, :3], E[:3, 3:]


@one_blas_thread
def simulate_actuator(rig: ActuatorRig | None = None, *, seed: int | None = 0,
                      linear: bool = False) -> pd.DataFrame:
    """Run one closed-loop built-in test of the actuator.

    Parameters
    ----------
    rig : ActuatorRig, optional
        Rig and test parameters; the shipped defaults if omitted.
    seed : int or None
        Seed of the perturbations and sensor noise (None: fresh entropy).
    linear : bool
        Switch every nonlinear effect off (Coulomb friction, voltage saturation,
        current quantisation), leaving an exactly linear closed loop.

    Returns
    -------
    pandas.DataFrame
        Columns ``t`` [s], ``V`` [V], ``I`` [A], ``omega`` [rad/s], ``position`` [m],
        ``yd`` [m], ``ud`` [V]. ``attrs["truth"]`` holds the true parameters
        ``R, L, Ke, Kt, J, D``.

    Example
    -------
    >>> rec = simulate_actuator(seed=1)
    >>> list(rec.columns)
    ['t', 'V', 'I', 'omega', 'position', 'yd', 'ud']
    >>> len(rec)
    4000
    """
    rig = rig if rig is not None else load_actuator_rig()
    rng = np.random.default_rng(seed)
    fs, dt = rig.sample_rate, rig.dt
    n = int(round(rig.duration * fs))
    yd = band_limited_noise(n, rig.yd_std, rig.yd_bandwidth, fs, rng)
    ud = band_limited_noise(n, rig.ud_std, rig.ud_bandwidth, fs, rng)
    noise_i = band_limited_noise(n, rig.noise_I, rig.noise_bandwidth, fs, rng)
    noise_w = band_limited_noise(n, rig.noise_omega, rig.noise_bandwidth, fs, rng)

    coulomb = 0.0 if linear else rig.coulomb_friction
    saturate = rig.saturation and not linear
    quant = 0.0 if linear else rig.current_quantisation
    nsub = rig.substeps if coulomb > 0 else 1
    Ad, Bd = _zoh_matrices(rig, dt / nsub)
    a = Ad.tolist()
    b = Bd.tolist()
    # Hot loop in plain floats: ~20x faster than small numpy operations per step.
    a00, a01, a02 = a[0]
    a10, a11, a12 = a[1]
    a20, a21, a22 = a[2]
    bv0, bt0 = b[0]
    bv1, bt1 = b[1]
    bv2, bt2 = b[2]
    p = rig.metres_per_radian
    kx, kp, ki, kc, vmax = (rig.kp_position, rig.kp_speed, rig.ki_speed * dt,
                            rig.k_current, rig.v_max)
    ws = rig.coulomb_smoothing

    V = np.empty(n)
    I_meas = np.empty(n)
    w_meas = np.empty(n)
    pos = np.empty(n)
    i = w = th = 0.0
    integ = 0.0
    yd_l, ud_l, ni_l, nw_l = yd.tolist(), ud.tolist(), noise_i.tolist(), noise_w.tolist()
    for k in range(n):
        im = i + ni_l[k]
        if quant > 0.0:
            im = quant * round(im / quant)
        wm = w + nw_l[k]
        I_meas[k] = im
        w_meas[k] = wm
        pos[k] = th * p
        e_w = kx * (yd_l[k] / p - th) - wm
        v = kp * e_w + integ - kc * im + ud_l[k]
        if saturate and (v > vmax or v < -vmax):
            v = vmax if v > 0 else -vmax  # conditional integration: hold the integrator
        else:
            integ += ki * e_w
        V[k] = v
        for _ in range(nsub):
            tf = coulomb * math.tanh(w / ws) if coulomb > 0.0 else 0.0
            i, w, th = (a00 * i + a01 * w + a02 * th + bv0 * v + bt0 * tf,
                        a10 * i + a11 * w + a12 * th + bv1 * v + bt1 * tf,
                        a20 * i + a21 * w + a22 * th + bv2 * v + bt2 * tf)

    if not (np.all(np.isfinite(V)) and np.all(np.isfinite(w_meas))):
        raise ConfigError("the simulated loop diverged: the controller gains make it "
                          "unstable for these plant parameters")
    t = np.arange(n) * dt
    rec = pd.DataFrame({"t": t, "V": V, "I": I_meas, "omega": w_meas, "position": pos,
                        "yd": yd, "ud": ud})
    rec.attrs["truth"] = rig.physical()
    return rec
