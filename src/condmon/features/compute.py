"""Computing declared signal features over a record's windows.

Each feature (:class:`~condmon.models.features.FeatureSpec`) is one statistic
of one channel in the windows of the regimes it names. Its value over a
regime is the sample-weighted mean of its value in each window of that regime.

**Its standard error** is the batch-means one (the one definition used for
every feature): each window is cut into ``B`` contiguous blocks of equal
length (``B = min(8, n // 32)``, at least 2), the statistic is taken on each
block, and the standard error of the window's value is the blocks' sample
standard deviation over ``sqrt(B)``. It holds the signal's own variability
within the record, serial correlation included as far as a block is longer
than the signal's correlation time; for the extreme-value statistics (crest,
peak-to-peak) it is an approximation of the same order. The record-to-record
scatter of a healthy unit, which the monitor judges a change against, is
usually larger: it is measured from the baseline's records, not from this.

The statistics are scipy's where scipy has them (``scipy.stats.kurtosis``,
``scipy.signal.welch``, ``scipy.integrate.trapezoid``); RMS, standard
deviation, mean, peak-to-peak and crest factor are one numpy reduction each.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError, DataError
from condmon.models.features import FeatureSpec, check_band
from condmon.models.regimes import regime_key

__all__ = ["FeatureEstimate", "feature_statistic", "compute_features", "spans_for"]

FloatArray = NDArray[np.float64]

#: Fewest samples a window needs for a feature (two blocks of 16).
MIN_SAMPLES = 32
#: Most blocks a window is cut into for the batch-means standard error.
MAX_BLOCKS = 8
#: Shortest Welch segment (longer when a narrow band needs it). [samples]
WELCH_SEGMENT = 256
#: Frequency bins a band power's band holds at least: the Welch segment is
#: lengthened (a power of 2) until the bin spacing is a quarter of the band.
BAND_BINS = 4


def welch_segment(sample_rate: float, band: tuple[float, float]) -> int:
    """The Welch segment [samples] whose bins resolve ``band`` [Hz]: at least
    :data:`WELCH_SEGMENT`, a power of 2, with :data:`BAND_BINS` bins in the band.

    Example
    -------
    >>> welch_segment(10000.0, (40.0, 200.0)), welch_segment(10000.0, (580.0, 600.0))
    (256, 2048)
    """
    width = max(band[1] - band[0], 1e-300)
    need = BAND_BINS * sample_rate / width
    return max(WELCH_SEGMENT, 1 << max(0, math.ceil(math.log2(min(need, 2.0 ** 40)))))


@dataclass(frozen=True)
class FeatureEstimate:
    """The features of one record.

    Attributes
    ----------
    values : dict of str to (float, float)
        ``{name@regime: (value, standard error)}`` in the feature's unit.
    units : dict of str to str
        Unit of each feature, by feature name (``vib_stroke``).
    notes : tuple of str
        What the user should know (a window too short, a flat channel).
    """

    values: dict[str, tuple[float, float]]
    units: dict[str, str]
    notes: tuple[str, ...] = ()


def feature_statistic(x: FloatArray, statistic: str, sample_rate: float,
                      band: tuple[float, float] | None = None) -> float:
    """One statistic of one signal segment.

    Parameters
    ----------
    x : ndarray, shape (n,)
        The channel's samples. [channel unit]
    statistic : str
        One of :data:`condmon.models.features.STATISTICS`.
    sample_rate : float
        [Hz]
    band : (float, float), optional
        ``band_power``'s band. [Hz]

    Returns
    -------
    float
        NaN where the statistic is undefined (the kurtosis or crest factor of
        a constant signal; a band holding no frequency bin of the segment).

    Example
    -------
    >>> t = np.arange(2000) / 1000.0
    >>> x = np.sin(2 * np.pi * 50.0 * t)
    >>> round(feature_statistic(x, "rms", 1000.0), 4), round(feature_statistic(x, "crest", 1000.0), 3)
    (0.7071, 1.414)
    >>> round(feature_statistic(x, "band_power", 1000.0, (40.0, 60.0)), 2)   # its variance
    0.5
    """
    if statistic == "mean":
        return float(np.mean(x))
    if statistic == "rms":
        return float(np.sqrt(np.mean(x * x)))
    if statistic == "peak_to_peak":
        return float(np.ptp(x))
    sd = float(np.std(x))
    if statistic == "std":
        return float(np.std(x, ddof=1))
    if statistic == "band_power":
        from scipy.integrate import trapezoid
        from scipy.signal import welch

        assert band is not None
        f, pxx = welch(x, fs=sample_rate, nperseg=min(welch_segment(sample_rate, band), x.size))
        inside = (f >= band[0]) & (f <= band[1])
        if np.count_nonzero(inside) < 2:
            return math.nan
        return float(trapezoid(pxx[inside], f[inside]))
    if not sd > 1e-12 * max(float(np.max(np.abs(x))), 1e-300):
        return math.nan  # a constant segment has no shape
    if statistic == "crest":
        return float(np.max(np.abs(x - np.mean(x)))) / sd
    if statistic == "kurtosis":
        from scipy.stats import kurtosis

        return float(kurtosis(x, fisher=False))
    raise ConfigError(f"unknown statistic {statistic!r}")


def _window(x: FloatArray, spec: FeatureSpec, fs: float) -> tuple[float, float]:
    """Value and batch-means standard error of ``spec`` over one window."""
    value = feature_statistic(x, spec.statistic, fs, spec.band)
    # a band power's block holds one whole Welch segment at least
    shortest = welch_segment(fs, spec.band) if spec.band is not None else 32
    blocks = max(2, min(MAX_BLOCKS, x.size // shortest))
    parts = np.array([feature_statistic(b, spec.statistic, fs, spec.band)
                      for b in np.array_split(x, blocks)])
    parts = parts[np.isfinite(parts)]
    if parts.size < 2 or not math.isfinite(value):
        return value, math.nan
    return value, float(np.std(parts, ddof=1) / math.sqrt(parts.size))


def spans_for(spec: FeatureSpec, windows: Sequence[tuple[str, int, int, bool]]
              ) -> dict[str, list[tuple[int, int]]]:
    """The row spans of each regime ``spec`` is computed in.

    Parameters
    ----------
    spec : FeatureSpec
    windows : sequence of (regime label, first, stop, used)
        A record's windows; a label may carry the metadata that split it
        (``forward, load=ball``).

    Returns
    -------
    dict
        ``{regime label: [(first, stop), ...]}``: the windows of the regimes
        ``spec`` names, or every used window when it names none.

    Example
    -------
    >>> f = FeatureSpec("vib", "acc", "std", regimes=("holding",))
    >>> spans_for(f, [("forward", 10, 400, True), ("holding", 420, 3000, False)])
    {'holding': [(420, 3000)]}
    """
    out: dict[str, list[tuple[int, int]]] = {}
    for label, first, stop, used in windows:
        # a pooled label (``forward + reverse``: records estimated together) counts
        # when each regime in it does
        bases = [part.split(",")[0].strip() for part in label.split(" + ")]
        if all(b in spec.regimes for b in bases) if spec.regimes else used:
            out.setdefault(label, []).append((first, stop))
    return out


def compute_features(columns: Mapping[str, FloatArray], sample_rate: float,
                     windows: Sequence[tuple[str, int, int, bool]],
                     specs: Sequence[FeatureSpec], source: str = "record",
                     declaration: str = "the declaration", what: str = "feature",
                     available: Sequence[str] | None = None) -> FeatureEstimate:
    """The declared features of one record.

    Parameters
    ----------
    columns : mapping of str to ndarray
        The record's validated columns (after ``[record]`` scaling).
    sample_rate : float
        [Hz]
    windows : sequence of (regime label, first, stop, used)
        The record's windows (one ``("", 0, n, True)`` for a machine without
        regimes).
    specs : sequence of FeatureSpec
    source : str
        The record, named in messages.
    declaration : str
        The declaration file, named in messages.
    what : str
        What the specs are, in messages: ``feature`` (``[features]``) or
        ``condition`` (``[conditions]``).
    available : sequence of str, optional
        Every column the record file has (after ``[record]``), named when a
        channel is missing (default: ``columns``'s).

    Returns
    -------
    FeatureEstimate

    Raises
    ------
    DataError
        A required feature's channel is not a column of the record (naming
        the record, the feature and the record's columns); a feature declared
        ``required = false`` is left out with a note.
    ConfigError
        A band above the record's Nyquist frequency.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> cols = {"acc": rng.normal(0.0, 2.0, 4000)}
    >>> f = FeatureSpec("vib", "acc", "std", unit="m/s^2")
    >>> est = compute_features(cols, 1000.0, [("", 0, 4000, True)], [f])
    >>> v, se = est.values["vib"]
    >>> round(v, 1), se < 0.05
    (2.0, True)
    """
    values: dict[str, tuple[float, float]] = {}
    notes: list[str] = []
    for spec in specs:
        if spec.channel not in columns and not spec.required:
            notes.append(f"{what} {spec.name} not computed: the record has no column "
                         f"{spec.channel!r} (required = false)")
            continue
        if spec.channel not in columns:
            have = sorted(str(k) for k in (available if available is not None else columns)
                          if k != "t")
            raise DataError(f"{source}: {what} {spec.name!r} ({declaration}[{what}s."
                            f"{spec.name}]) names channel {spec.channel!r}, which the record "
                            f"does not have; its columns: {', '.join(have)}")
        try:
            check_band(spec, sample_rate, declaration)
        except ConfigError as err:
            raise ConfigError(f"{source}: {err}") from None
        x = np.asarray(columns[spec.channel], dtype=np.float64)
        for label, spans in spans_for(spec, windows).items():
            parts = [(_window(x[a:b], spec, sample_rate), b - a) for a, b in spans
                     if b - a >= MIN_SAMPLES]
            parts = [(v, n) for v, n in parts if math.isfinite(v[0]) and math.isfinite(v[1])]
            if not parts:
                notes.append(f"{what} {spec.name} not computed in regime {label or '(all)'}: "
                             + _why_undefined(spec, sample_rate, spans))
                continue
            w = np.array([n for _, n in parts], dtype=np.float64)
            w /= w.sum()
            v = float(np.dot(w, [p[0] for p, _ in parts]))
            se = float(np.sqrt(np.dot(w ** 2, [p[1] ** 2 for p, _ in parts])))
            values[regime_key(spec.name, label)] = (v, se)
    return FeatureEstimate(values, {s.name: s.unit for s in specs}, tuple(notes))


def _why_undefined(spec: FeatureSpec, fs: float, spans: Sequence[tuple[int, int]]) -> str:
    """Why no window gave ``spec`` a value (and a standard error)."""
    longest = max((b - a for a, b in spans), default=0)
    if spec.band is not None:
        seg = welch_segment(fs, spec.band)
        return (f"its band {spec.band[0]:g}..{spec.band[1]:g} Hz "
                f"({spec.band[1] - spec.band[0]:g} Hz wide) needs windows of 2 x {seg} samples "
                f"({BAND_BINS} frequency bins in the band at {fs:g} Hz, in two blocks for its "
                f"standard error); the longest window has {longest}")
    return (f"no window of {MIN_SAMPLES} samples or more with a defined {spec.statistic} "
            f"(the longest has {longest} samples)")
