"""Detection on a stream: the offline threshold test, fed chunk by chunk.

:func:`condmon.diagnose.residuals.detect` judges a whole record at once. A
stream arrives in chunks, and the same test must give the same answer at the
same sample, whatever the chunking. :class:`OnlineDetector` carries what the
test needs from one chunk to the next: the last residuals of the moving
average's window, the length of each residual's current run outside its band,
when that run began, when the stream started (the start-up is not judged) and
the known inputs' operating point (the ``input_settle`` time after a step is not
judged). It holds one unit's residuals of the "simulation" set: one per
sensor, measured minus the model run from the known inputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.diagnose.residuals import DetectionSettings, Normalisation
from condmon.errors import DataError
from condmon.models.declared import PlantModel

__all__ = ["OnlineDetection", "OnlineDetector", "noise_figures"]

FloatArray = NDArray[np.float64]


def noise_figures(model: PlantModel, dt: float, settings: DetectionSettings) -> Normalisation:
    """The normalisation from the sensors' declared noise at sample interval ``dt`` [s]
    (as :func:`~condmon.diagnose.residuals.noise_normalisation` for a record).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> n = noise_figures(load_plant_model("hst"), 0.01, DetectionSettings())
    >>> n.names, round(float(n.std[0]))          # 2.5e4 Pa / sqrt(20 samples)
    (('r_Ps', 'r_omega_m'), 5590)
    """
    n = max(1, int(round(settings.window / dt)))
    raw = np.array([s.noise for s in model.sensors], dtype=np.float64)
    return Normalisation(tuple(f"r_{s.name}" for s in model.sensors), np.zeros(len(raw)),
                         raw / math.sqrt(n), raw, settings.window, "declared sensor noise")


@dataclass(frozen=True)
class OnlineDetection:
    """A detection on a stream.

    Attributes
    ----------
    time : float
        When the first residual had stayed outside ±1 for the persistence time. [s]
    onset : float
        When that residual left its band. [s]
    fired : tuple of str
        The residuals outside their band at ``time``.
    """

    time: float
    onset: float
    fired: tuple[str, ...]


@dataclass
class OnlineDetector:
    """One unit's debounced threshold test, chunk by chunk.

    Parameters
    ----------
    normalisation : Normalisation
        Mean and spread of each smoothed residual (:func:`noise_figures`, or
        learned from healthy records).
    settings : DetectionSettings
    dt : float
        The stream's sample interval. [s]

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> s = DetectionSettings()
    >>> d = OnlineDetector(noise_figures(load_plant_model("hst"), 0.01, s), s, 0.01)
    >>> t = np.arange(300) * 0.01
    >>> r = np.zeros((300, 2)); r[150:, 1] = 1.0          # omega_m 1 rad/s off from 1.5 s
    >>> [d.feed(t[:100], r[:100], np.zeros((100, 1))), d.feed(t[100:], r[100:],
    ...  np.zeros((200, 1)))][1]
    OnlineDetection(time=1.99, onset=1.5, fired=('r_omega_m',))
    """

    normalisation: Normalisation
    settings: DetectionSettings
    dt: float
    detected: OnlineDetection | None = None
    _start: float | None = field(default=None, repr=False)
    _tail: FloatArray = field(default_factory=lambda: np.empty((0, 0)), repr=False)
    _run: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    _onset: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    _level: FloatArray | None = field(default=None, repr=False)
    _level_n: int = field(default=0, repr=False)
    _settle_until: float = field(default=-math.inf, repr=False)

    def __post_init__(self) -> None:
        if not self.dt > 0:
            raise DataError(f"sample interval must be > 0 s, not {self.dt!r}")
        self.reset()

    @property
    def names(self) -> tuple[str, ...]:
        """Residual names."""
        return self.normalisation.names

    @property
    def window(self) -> int:
        """Samples in the moving average."""
        return max(1, int(round(self.normalisation.window / self.dt)))

    @property
    def need(self) -> int:
        """Samples a residual must stay outside its band to fire."""
        p = self.settings.persistence
        return max(1, int(round(p / self.dt))) if p > 0 else 1

    def reset(self) -> None:
        """Start again (a gap, a jump or a restart of the stream): the start-up
        is judged afresh and nothing of the past is averaged in."""
        k = len(self.names)
        self._start = None
        self._tail = np.empty((0, k))
        self._run = np.zeros(k, dtype=np.int64)
        self._onset = np.full(k, np.nan)
        self._level, self._level_n = None, 0
        self._settle_until = -math.inf
        self.detected = None

    def feed(self, t: FloatArray, residuals: FloatArray, inputs: FloatArray
             ) -> OnlineDetection | None:
        """Judge one chunk; the detection when it happens in this chunk, else None.

        Parameters
        ----------
        t : ndarray, shape (n,)
            Times of the chunk's samples, after the previous chunk's. [s]
        residuals : ndarray, shape (n, n_residuals)
            Measured − model, in the order of :attr:`names`. [sensor units]
        inputs : ndarray, shape (n, n_inputs)
            Known inputs (the operating point). [input units]
        """
        n = len(t)
        if n == 0:
            return None
        if self._start is None:
            self._start = float(t[0])
        w = self.window
        joined = np.vstack([self._tail, residuals])
        c = np.cumsum(np.vstack([np.zeros((1, joined.shape[1])), joined]), axis=0)
        k = np.arange(len(self._tail) + 1, len(joined) + 1)
        lo = np.maximum(k - w, 0)  # shorter at the start of a stream, as at a record's
        with np.errstate(all="ignore"):
            smooth = (c[k] - c[lo]) / (k - lo)[:, None]
            mean, std = self.normalisation.figures(inputs)
            normalised = (smooth - mean) / (self.settings.z * std)
        self._tail = joined[-(w - 1):] if w > 1 else joined[:0]
        outside = (np.abs(normalised) > 1.0) & self._judged(t, inputs)[:, None]
        # run lengths outside the band, carried over from the last chunk: a run
        # ends at the last sample inside (a carried run began before this chunk)
        idx = np.arange(n)[:, None]
        last_in = np.maximum.accumulate(np.where(outside, -1 - self._run[None, :], idx), axis=0)
        run = np.where(outside, idx - last_in, 0)
        onset = np.where(last_in + 1 >= 0, t[np.clip(last_in + 1, 0, n - 1)], self._onset[None, :])
        self._run = run[-1].astype(np.int64)
        self._onset = np.where(outside[-1], onset[-1], np.nan)
        if self.detected is not None:
            return None
        hit = np.flatnonzero((run >= self.need).any(axis=1))
        if not len(hit):
            return None
        i = int(hit[0])
        fired = run[i] >= self.need
        self.detected = OnlineDetection(float(t[i]), float(onset[i][fired].min()),
                                        tuple(nm for nm, f in zip(self.names, fired) if f))
        return self.detected

    def _judged(self, t: FloatArray, inputs: FloatArray) -> NDArray[np.bool_]:
        """After the start-up, and away from steps of the known inputs."""
        assert self._start is not None
        ok = t >= self._start + self.settings.startup
        if self.settings.input_settle <= 0 or inputs.shape[1] == 0:
            return ok
        for i in range(len(t)):
            u = inputs[i]
            if self._level is None:
                self._level, self._level_n = u.astype(np.float64).copy(), 1
            elif np.any(np.abs(u - self._level / self._level_n)
                        > 0.02 * np.maximum(np.abs(self._level / self._level_n), 1e-12)):
                self._level, self._level_n = u.astype(np.float64).copy(), 1
                self._settle_until = float(t[i]) + self.settings.input_settle
            else:
                self._level = self._level + u
                self._level_n += 1
            if t[i] < self._settle_until:
                ok[i] = False
        return ok
