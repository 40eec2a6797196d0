"""Cutting a record into windows of one operating regime each.

Every sample is tagged with the first declared regime whose condition holds
(:mod:`condmon.models.regimes`); a run of samples with one tag is a window.
``settle`` seconds are left out at both ends of each window (the transients
into and out of a regime: an actuator's start and its deceleration into the
end stop), and a window shorter than ``min_duration`` afterwards is not used.
A regime the declaration marks ``use = false`` (held against a stop) and
samples in no regime are reported, not used. A machine that declares no
regimes has one window: the whole record (or the span chosen by hand).

A pure function of the record's time, its signals and the declaration.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import DataError
from condmon.models.regimes import RegimeSpec

__all__ = ["Window", "cut_windows", "parse_window", "regime_label"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Window:
    """A span of a record in one regime.

    Attributes
    ----------
    start, end : float
        First and last sample used (after ``settle``); for a window not used,
        the regime's whole span. [s]
    regime : str
        The regime's name, with the metadata that split it (``forward,
        load=ball``); "" when the machine declares no regimes.
    used : bool
        Whether estimation may use it.
    why : str or None
        Why not, when not used.
    first, stop : int
        Row range ``[first, stop)`` of the samples used.
    source : str
        The record it is a window of.
    """

    start: float
    end: float
    regime: str
    used: bool
    why: str | None
    first: int
    stop: int
    source: str = ""

    @property
    def duration(self) -> float:
        """``end - start``. [s]"""
        return self.end - self.start

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``source``, ``start``, ``end`` [s], ``regime``, ``used``, ``why``)."""
        return {"source": self.source, "start": float(self.start), "end": float(self.end),
                "regime": self.regime, "used": self.used, "why": self.why}


def regime_label(name: str, fields: tuple[str, ...], metadata: Mapping[str, Any]) -> str:
    """A regime's label with the metadata that split it.

    Example
    -------
    >>> regime_label("forward", ("load",), {"load": "ball"})
    'forward, load=ball'
    >>> regime_label("forward", ("load",), {})
    'forward, load=?'
    """
    parts = [name] + [f"{k}={metadata.get(k, '?')}" for k in fields]
    return ", ".join(p for p in parts if p)


def parse_window(text: str | None) -> tuple[float, float] | None:
    """``"1.5:4"`` -> ``(1.5, 4.0)`` [s]; an empty side means the record's start or end.

    Example
    -------
    >>> parse_window("0.5:2"), parse_window(":2")
    ((0.5, 2.0), (-inf, 2.0))
    """
    if text is None or not str(text).strip():
        return None
    raw = str(text).strip()
    if raw.count(":") != 1:
        raise DataError(f"--window {raw!r}: write START:END in seconds, e.g. 0.5:2.5")
    a, b = (s.strip() for s in raw.split(":"))
    try:
        lo = float(a) if a else -np.inf
        hi = float(b) if b else np.inf
    except ValueError:
        raise DataError(f"--window {raw!r}: START and END must be numbers [s]") from None
    if np.isnan(lo) or np.isnan(hi) or not lo < hi:
        raise DataError(f"--window {raw!r}: START must be below END")
    return lo, hi


def _span_rows(t: FloatArray, span: tuple[float, float] | None, source: str) -> tuple[int, int]:
    if span is None:
        return 0, t.size
    lo, hi = span
    first = int(np.searchsorted(t, lo, side="left"))
    stop = int(np.searchsorted(t, hi, side="right"))
    if stop - first < 2:
        raise DataError(f"{source}: the window {lo:g}:{hi:g} s lies outside the record "
                        f"({t[0]:g} to {t[-1]:g} s) or holds fewer than 2 samples")
    return first, stop


def cut_windows(t: FloatArray, signals: Mapping[str, FloatArray], spec: RegimeSpec,
                metadata: Mapping[str, Any] | None = None, *, source: str = "record",
                span: tuple[float, float] | None = None, edge: int = 0) -> tuple[Window, ...]:
    """Windows of a record, each in one regime.

    Parameters
    ----------
    t : ndarray
        Time, uniformly sampled. [s]
    signals : mapping of str to ndarray
        The signals the conditions may name (record columns and the states a
        route derives), each shape ``t.shape``.
    spec : RegimeSpec
        The declaration's regimes (empty: one window, the whole span).
    metadata : mapping, optional
        The record's metadata fields (``load = "ball"``).
    source : str
        The record, named in messages.
    span : (float, float), optional
        A window chosen by hand ``[start, end]``: only samples inside are
        classified. [s]
    edge : int
        Samples left out at both ends of the record (a filter's transients).

    Returns
    -------
    tuple of Window
        In time order; those not used say why.

    Raises
    ------
    DataError
        ``span`` outside the record; a condition naming neither a column nor
        a metadata field.

    Example
    -------
    >>> from condmon.models.regimes import parse_regimes
    >>> spec = parse_regimes({"moving": {"when": "abs(w) > 0.5"},
    ...                       "held": {"when": "abs(w) <= 0.5", "use": False}}, "rig")
    >>> t = np.arange(10.0)
    >>> w = np.r_[np.ones(6), np.zeros(4)]
    >>> [(x.regime, x.used, x.first, x.stop) for x in cut_windows(t, {"w": w}, spec)]
    [('moving', True, 0, 6), ('held', False, 6, 10)]
    """
    meta = dict(metadata or {})
    first, stop = _span_rows(t, span, source)
    first, stop = max(first, edge), min(stop, t.size - edge)
    if stop - first < 2:
        raise DataError(f"{source}: too few samples left for a window after the filter's "
                        f"edges ({edge} samples at each end)")
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    if not spec.regimes:
        label = regime_label("", spec.metadata, meta)
        return (Window(float(t[first]), float(t[stop - 1]), label, True, None, first, stop,
                       source),)
    tags = np.full(t.size, -1, dtype=np.int64)
    free = np.ones(t.size, dtype=bool)
    for i, regime in enumerate(spec.regimes):
        hold = regime.condition.evaluate(signals, meta, t.size, source) & free
        tags[hold] = i
        free &= ~hold
    tags[:first] = -2
    tags[stop:] = -2
    edges = np.flatnonzero(np.diff(tags)) + 1
    bounds = np.r_[0, edges, t.size]
    out: list[Window] = []
    settle = int(round(spec.settle / dt)) if dt > 0 else 0
    for a, b in zip(bounds[:-1], bounds[1:]):
        tag = int(tags[a])
        if tag == -2:
            continue
        if tag == -1:
            out.append(Window(float(t[a]), float(t[b - 1]), "(none)", False,
                              "no regime's condition holds", int(a), int(b), source))
            continue
        regime = spec.regimes[tag]
        label = regime_label(regime.name, spec.metadata, meta)
        if not regime.use:
            out.append(Window(float(t[a]), float(t[b - 1]), label, False,
                              regime.why or "the declaration does not use this regime",
                              int(a), int(b), source))
            continue
        lo, hi = a + settle, b - settle
        if hi - lo < 2 or (t[hi - 1] - t[lo]) < spec.min_duration:
            left = max(0.0, float(t[hi - 1] - t[lo])) if hi - lo >= 2 else 0.0
            out.append(Window(float(t[a]), float(t[b - 1]), label, False,
                              f"{left:.3g} s left after {spec.settle:g} s settling at each end"
                              f" (shorter than {spec.min_duration:g} s)", int(a), int(b),
                              source))
            continue
        out.append(Window(float(t[lo]), float(t[hi - 1]), label, True, None, int(lo), int(hi),
                          source))
    return tuple(out)
