"""Many copies of one plant model, advanced sample by sample beside their streams.

Online monitoring runs the model beside each unit's stream, chunk by chunk: its
states are carried from one chunk to the next, never re-simulated from zero.
A service watches many units of one model, so the copies are advanced together:
the states of every unit are the columns of one array, and one call of the
model's vectorised right-hand side serves them all.

The integration is the classical fourth-order Runge-Kutta method with a fixed
number of sub-steps per sample (``substeps``, data: ``[online]`` of
``condmon/data/isolation.toml``), the known inputs held over the sample (as a
data logger holds them). An adaptive solver (LSODA, as offline) per unit and per
chunk would cost milliseconds per call; the fixed step costs microseconds per
unit-sample, and on the shipped HST at 100 Hz with 10 sub-steps it stays within
1e-3 of the sensors' noise of the offline solution (``tests/test_online.py``).
A copy whose states stop being finite is reported, so its unit can be reset.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError
from condmon.models.declared import CompiledModel, PlantModel

__all__ = ["BatchStepper"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass
class BatchStepper:
    """The states of ``capacity`` copies of ``model``; slots are handed to units.

    Attributes
    ----------
    model : PlantModel
    substeps : int
        Runge-Kutta steps per sample.
    params : mapping, optional
        Parameter values replacing the declared ones (every copy alike). [SI]

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> s = BatchStepper(load_plant_model("hst"))
    >>> a, b = s.add(), s.add()
    >>> u = np.full((1, 2), 152.0)                 # pump speed of both [rad/s]
    >>> for _ in range(500):                       # 5 s at 100 Hz
    ...     y = s.step(np.array([a, b]), u, np.full(2, 0.01))
    >>> y.shape, round(float(y[1, 0]), 1)          # (sensors, units); omega_m [rad/s]
    ((2, 2), 14.3)
    """

    model: PlantModel
    substeps: int = 10
    params: Mapping[str, float] | None = None
    _compiled: CompiledModel = field(init=False, repr=False)
    _p: FloatArray = field(init=False, repr=False)
    _x: FloatArray = field(init=False, repr=False)
    _free: list[int] = field(init=False, repr=False, default_factory=list)

    def __post_init__(self) -> None:
        if self.substeps < 1:
            raise ConfigError(f"substeps must be >= 1, not {self.substeps}")
        self._compiled = self.model.compile()
        self._p = self._compiled.parameter_vector(self.params)
        self._x = np.empty((len(self.model.states), 0), dtype=np.float64)

    @property
    def initial(self) -> FloatArray:
        """The declared initial states, shape (n_states,). [state units]"""
        return np.array([s.initial for s in self.model.states], dtype=np.float64)

    def add(self) -> int:
        """A slot for a new copy, at the declared initial states."""
        if self._free:
            slot = self._free.pop()
        else:
            slot = self._x.shape[1]
            grown = np.empty((self._x.shape[0], max(8, 2 * slot)), dtype=np.float64)
            grown[:, :slot] = self._x
            self._free.extend(range(grown.shape[1] - 1, slot, -1))
            self._x = grown
        self._x[:, slot] = self.initial
        return slot

    def release(self, slot: int) -> None:
        """Give a slot back (its unit has left)."""
        self._free.append(slot)

    def reset(self, slots: Sequence[int] | IntArray) -> None:
        """Start copies again from the declared initial states."""
        self._x[:, np.asarray(slots, dtype=np.intp)] = self.initial[:, None]

    def set_states(self, slot: int, values: Mapping[str, float]) -> None:
        """Start one copy from given states (others at their declared initial).
        [state units]"""
        x = self.initial
        for i, st in enumerate(self.model.states):
            if st.name in values:
                x[i] = float(values[st.name])
        self._x[:, slot] = x

    def states(self, slots: Sequence[int] | IntArray) -> FloatArray:
        """The states of copies, shape (n_states, len(slots)). [state units]"""
        return self._x[:, np.asarray(slots, dtype=np.intp)].copy()

    def outputs(self, slots: Sequence[int] | IntArray, u: FloatArray) -> FloatArray:
        """Noise-free sensor readings at the current states, (n_sensors, len(slots))."""
        x = self._x[:, np.asarray(slots, dtype=np.intp)]
        with np.errstate(all="ignore"):
            return self._compiled.outputs_batch(x, u, self._p)

    def step(self, slots: Sequence[int] | IntArray, u: FloatArray, dt: FloatArray
             ) -> FloatArray:
        """Advance copies by one sample each and return their sensor readings.

        Parameters
        ----------
        slots : sequence of int
            The copies to advance (each once).
        u : ndarray, shape (n_inputs, len(slots))
            Known inputs, held over the sample. [input units]
        dt : ndarray, shape (len(slots),)
            Each copy's sample interval. [s]

        Returns
        -------
        ndarray, shape (n_sensors, len(slots))
            Readings at the end of the sample; a copy whose states are no
            longer finite gives NaN (the caller resets it).
        """
        idx = np.asarray(slots, dtype=np.intp)
        x = self._x[:, idx]
        h = np.asarray(dt, dtype=np.float64) / self.substeps
        f = self._compiled.rhs_batch
        p = self._p
        with np.errstate(all="ignore"):
            for _ in range(self.substeps):
                k1 = f(x, u, p)
                k2 = f(x + 0.5 * h * k1, u, p)
                k3 = f(x + 0.5 * h * k2, u, p)
                k4 = f(x + h * k3, u, p)
                x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            self._x[:, idx] = x
            y = self._compiled.outputs_batch(x, u, p)
        bad = ~np.all(np.isfinite(x), axis=0)
        if bad.any():
            y[:, bad] = np.nan
        return y

