"""Signal features declared as data: statistics of a record's channels in a regime's windows.

A physical parameter says how the machine behaves; a signal feature says what
its sensors show while it does. Gear and bearing damage shows in vibration
during motion, while a leaking seal is quiet: a feature beside the parameters
tells such faults apart. A declaration names its features in a ``[features]``
table; each is computed per regime (:mod:`condmon.features`), stored under
``name@regime`` like a regime's parameter, and baselined, trended, checked and
named in rules exactly like one.

.. code-block:: toml

    [features.vib_stroke]
    channel = "acc3"              # a record column after [record] (model or file name)
    statistic = "std"             # rms, std, kurtosis, crest, peak_to_peak, mean, band_power
    regimes = ["forward", "reverse"]   # default: every regime the estimation uses
    unit = "m/s^2"
    description = "vibration of the shaft housing during a stroke"

    [features.mesh]
    channel = "acc3"
    statistic = "band_power"
    band = [40.0, 100.0]          # [Hz], band_power only
    unit = "(m/s^2)^2"

This module reads and validates the table; a band is checked against the
Nyquist frequency when the declaration's ``[record]`` states a sample rate,
else against each record's.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from condmon.errors import ConfigError

__all__ = ["FeatureSpec", "STATISTICS", "parse_features", "check_band", "ConditionSpec",
           "parse_conditions"]

#: The statistics a feature may take, with what each is (for messages and docs).
STATISTICS: dict[str, str] = {
    "rms": "root mean square of the channel [channel unit]",
    "std": "standard deviation about the window's mean [channel unit]",
    "kurtosis": "kurtosis (Pearson: 3 for a normal signal) [-]",
    "crest": "crest factor: largest |x - mean| over the standard deviation [-]",
    "peak_to_peak": "largest minus smallest value [channel unit]",
    "mean": "mean [channel unit]",
    "band_power": "power in a frequency band (Welch's periodogram) [channel unit^2]",
}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_KEYS = ("channel", "statistic", "regimes", "band", "unit", "description", "required")


@dataclass(frozen=True)
class FeatureSpec:
    """One declared signal feature.

    Attributes
    ----------
    name : str
        Its name in the history and in rules (``vib_stroke``).
    channel : str
        The record column it is a statistic of (after ``[record]``).
    statistic : str
        One of :data:`STATISTICS`.
    regimes : tuple of str
        The regimes whose windows it is computed in; empty: every regime the
        estimation uses.
    band : tuple of float or None
        ``(low, high)`` of a band power. [Hz]
    unit : str
    description : str
    required : bool
        Whether a record without the channel is refused (one line naming the
        channel); ``required = false``: it is estimated without the feature,
        and a note says so (a rig channel some records lack, such as a
        simulated built-in test's).
    """

    name: str
    channel: str
    statistic: str
    regimes: tuple[str, ...] = ()
    band: tuple[float, float] | None = None
    unit: str = ""
    description: str = ""
    required: bool = True

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"name": self.name, "channel": self.channel, "statistic": self.statistic,
                "regimes": list(self.regimes), "band_hz": list(self.band) if self.band else None,
                "unit": self.unit, "description": self.description}


def check_band(spec: FeatureSpec, sample_rate: float, where: str) -> None:
    """Raise :class:`ConfigError` when ``spec``'s band reaches past the Nyquist
    frequency of ``sample_rate`` [Hz].

    Example
    -------
    >>> f = FeatureSpec("mesh", "acc", "band_power", band=(40.0, 200.0))
    >>> check_band(f, 250.0, "rig.toml")
    Traceback (most recent call last):
    ...
    condmon.errors.ConfigError: rig.toml[features.mesh].band: 200 Hz is above the Nyquist frequency 125 Hz of a 250 Hz record; allowed: a band within 0 .. 125 Hz
    """
    if spec.band is None:
        return
    nyquist = sample_rate / 2.0
    if spec.band[1] > nyquist:
        raise ConfigError(f"{where}[features.{spec.name}].band: {spec.band[1]:g} Hz is above "
                          f"the Nyquist frequency {nyquist:g} Hz of a {sample_rate:g} Hz "
                          f"record; allowed: a band within 0 .. {nyquist:g} Hz")


def _band(value: Any, at: str) -> tuple[float, float]:
    ok = (isinstance(value, list) and len(value) == 2
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                  for v in value))
    if not ok or not 0.0 <= float(value[0]) < float(value[1]):
        raise ConfigError(f"{at}.band must be [low, high] in Hz with 0 <= low < high, "
                          f"not {value!r}")
    return float(value[0]), float(value[1])


def _entries(table: Mapping[str, Any] | None, source: str, kind: str, keys: tuple[str, ...],
             needs: str) -> list[tuple[str, str, Mapping[str, Any]]]:
    """The ``[kind.NAME]`` entries of a table as ``(name, where, entry)``, each
    a table of ``keys`` only; :class:`ConfigError` naming the file otherwise."""
    if not table:
        return []
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}[{kind}] must be a table of entries ([{kind}.NAME] with "
                          f"{needs})")
    out = []
    for name, entry in table.items():
        at = f"{source}[{kind}.{name}]"
        if not isinstance(entry, Mapping):
            raise ConfigError(f"{at} must be a table with {needs}")
        extra = [k for k in entry if k not in keys]
        if extra:
            raise ConfigError(f"{at}: unknown key {extra[0]!r}; allowed: {', '.join(keys)}")
        out.append((str(name), at, entry))
    return out


def parse_features(table: Mapping[str, Any] | None, source: str, *,
                   reserved: tuple[str, ...] = (), regimes: tuple[str, ...] = (),
                   sample_rate: float | None = None, kind: str = "features"
                   ) -> tuple[FeatureSpec, ...]:
    """Read and validate a declaration's ``[features]`` table.

    Parameters
    ----------
    table : mapping or None
        ``{name: {channel, statistic, regimes, band, unit, description}}``.
    source : str
        The declaration file, named in every message.
    reserved : tuple of str
        Names already taken (the reported parameters).
    regimes : tuple of str
        The declared regimes a feature may name (empty: the declaration has
        none, and a feature names none).
    sample_rate : float, optional
        The ``[record]`` sample rate, when declared: bands are checked against
        its Nyquist frequency. [Hz]
    kind : str
        The table's name in messages (``conditions`` for a condition's statistic).

    Returns
    -------
    tuple of FeatureSpec

    Raises
    ------
    ConfigError
        Naming the file, the feature and the allowed values.

    Example
    -------
    >>> fs = parse_features({"vib": {"channel": "acc", "statistic": "std"}}, "rig.toml")
    >>> fs[0].name, fs[0].channel, fs[0].statistic
    ('vib', 'acc', 'std')
    """
    out = []
    for name, at, entry in _entries(table, source, kind, _KEYS, "channel and statistic"):
        if not _NAME.match(name) or "@" in name:
            raise ConfigError(f"{at}: a feature's name holds letters, digits and _ and does "
                              "not start with a digit")
        if name in reserved:
            raise ConfigError(f"{at}: {name!r} is already a reported parameter; "
                              "give the feature another name")
        channel = entry.get("channel")
        if not isinstance(channel, str) or not channel.strip():
            raise ConfigError(f"{at}.channel must name a record column (after [record]), "
                              f"not {channel!r}")
        stat = entry.get("statistic")
        if stat not in STATISTICS:
            raise ConfigError(f"{at}.statistic: unknown statistic {stat!r}; allowed: "
                              f"{', '.join(STATISTICS)}")
        band = None
        if stat == "band_power":
            if "band" not in entry:
                raise ConfigError(f"{at}: a band_power needs band = [low, high] in Hz")
            band = _band(entry["band"], at)
        elif "band" in entry:
            raise ConfigError(f"{at}.band is for statistic = \"band_power\" only, not {stat!r}")
        names = entry.get("regimes", [])
        if isinstance(names, str):
            names = [names]
        if not isinstance(names, list) or not all(isinstance(r, str) for r in names):
            raise ConfigError(f"{at}.regimes must be a list of regime names")
        unknown = [r for r in names if r not in regimes]
        if unknown:
            raise ConfigError(f"{at}.regimes: unknown regime {unknown[0]!r}; allowed: "
                              f"{', '.join(regimes) or 'none (the declaration has no [regimes])'}")
        required = entry.get("required", True)
        if not isinstance(required, bool):
            raise ConfigError(f"{at}.required must be true or false, not {required!r}")
        # a ratio's unit is "-" whatever the channel's (none given: kurtosis, crest)
        unit = str(entry.get("unit", "") or ("-" if STATISTICS[str(stat)].endswith("[-]")
                                             else ""))
        spec = FeatureSpec(name, channel.strip(), str(stat), tuple(names), band, unit,
                           str(entry.get("description", "")), required)
        if sample_rate is not None:
            check_band(spec, sample_rate, source)
        out.append(spec)
    return tuple(out)


@dataclass(frozen=True)
class ConditionSpec:
    """One declared operating condition (``[conditions]``): a covariate the
    healthy value of every parameter and feature is fitted against.

    Attributes
    ----------
    name : str
    feature : FeatureSpec or None
        A statistic of a record channel in the regimes' windows (``mean`` by
        default): an oil temperature, a supply pressure.
    metadata : str or None
        Or a numeric metadata field of the record (``load``, ``hours``).
    session_gap : float or None
        Or the time since the session started: since the first of the unit's
        records that follow each other with no pause longer than this gap
        (``since = "session start"``, ``gap``), from each record's start time
        (its date, or the time its file name holds: ``[record] name_time``). [s]
    unit : str
    description : str
    between_units : bool
        Whether its level means the same on another unit (a calibrated sensor,
        a metadata field). A raw channel's level is its own sensor's: against
        peers it is not used, and the check says so.
    """

    name: str
    feature: FeatureSpec | None = None
    metadata: str | None = None
    unit: str = ""
    description: str = ""
    between_units: bool = False
    session_gap: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"name": self.name, "channel": self.feature.channel if self.feature else None,
                "statistic": self.feature.statistic if self.feature else None,
                "metadata": self.metadata, "session_gap": self.session_gap,
                "unit": self.unit,
                "description": self.description, "between_units": self.between_units}


_CONDITION_KEYS = ("channel", "statistic", "regimes", "metadata", "since", "gap", "unit",
                   "description", "between_units", "required")
#: What ``since`` may name, and the pause that ends a session by default: a
#: pause of half an hour is no pause between the cycles of one run. [s]
SESSION_START, SESSION_GAP = "session start", 1800.0


def parse_conditions(table: Mapping[str, Any] | None, source: str, *,
                     reserved: tuple[str, ...] = (), regimes: tuple[str, ...] = ()
                     ) -> tuple[ConditionSpec, ...]:
    """Read and validate a declaration's ``[conditions]`` table.

    Each entry is a record channel's statistic in the regimes' windows
    (``channel``, ``statistic`` = ``mean`` by default, ``regimes``), a
    numeric metadata field (``metadata = "load"``), or the time since the
    session started (``since = "session start"``, with ``gap``, the longest
    pause within a session [s], 1800 by default), with ``unit``,
    ``description`` and ``between_units`` (default false for a channel,
    true otherwise).

    Raises
    ------
    ConfigError
        Naming the file, the condition and the allowed values.

    Example
    -------
    >>> cs = parse_conditions({"oil": {"channel": "T1"}, "load": {"metadata": "load"},
    ...                        "warm": {"since": "session start", "gap": 600}}, "rig.toml")
    >>> [(c.name, c.feature.statistic if c.feature else c.metadata or c.session_gap) for c in cs]
    [('oil', 'mean'), ('load', 'load'), ('warm', 600.0)]
    """
    out = []
    for name, at, entry in _entries(table, source, "conditions", _CONDITION_KEYS,
                                    "channel, metadata or since"):
        if sum(k in entry for k in ("channel", "metadata", "since")) != 1:
            raise ConfigError(f"{at} needs exactly one of channel (a record column), "
                              f"metadata (a metadata field) or since = {SESSION_START!r}")
        between = entry.get("between_units", "channel" not in entry)
        if not isinstance(between, bool):
            raise ConfigError(f"{at}.between_units must be true or false, not {between!r}")
        unit, text = str(entry.get("unit", "")), str(entry.get("description", ""))
        if "gap" in entry and "since" not in entry:
            raise ConfigError(f"{at}.gap is for since = {SESSION_START!r}")
        if "since" in entry:
            out.append(_session(name, at, entry, text, between))
            continue
        if "metadata" in entry:
            field_ = entry["metadata"]
            if not isinstance(field_, str) or not field_.strip():
                raise ConfigError(f"{at}.metadata must name a metadata field, not {field_!r}")
            bad = [k for k in ("statistic", "regimes", "required") if k in entry]
            if bad:
                raise ConfigError(f"{at}.{bad[0]} is for a channel's condition, not a "
                                  "metadata field's")
            out.append(ConditionSpec(name, None, field_.strip(), unit, text, between))
            continue
        feature = parse_features(
            {name: {"channel": entry["channel"], "statistic": entry.get("statistic", "mean"),
                    "regimes": entry.get("regimes", []), "unit": unit,
                    "required": entry.get("required", True)}},
            source, reserved=reserved, regimes=regimes, kind="conditions")[0]
        out.append(ConditionSpec(name, feature, None, unit, text, between))
    return tuple(out)


def _session(name: str, at: str, entry: Mapping[str, Any], text: str,
             between: bool) -> ConditionSpec:
    """A ``since = "session start"`` condition, checked."""
    if entry["since"] != SESSION_START:
        raise ConfigError(f"{at}.since must be {SESSION_START!r}, not {entry['since']!r}")
    bad = [k for k in ("statistic", "regimes", "required") if k in entry]
    if bad:
        raise ConfigError(f"{at}.{bad[0]} is for a channel's condition, not the session's time")
    gap = entry.get("gap", SESSION_GAP)
    if isinstance(gap, bool) or not isinstance(gap, (int, float)) or not 0 < gap < math.inf:
        raise ConfigError(f"{at}.gap must be the longest pause within a session, a number of "
                          f"seconds > 0, not {gap!r}")
    unit = str(entry.get("unit", "s"))
    if unit != "s":
        raise ConfigError(f"{at}.unit: the time since the session started is in s, not {unit!r}")
    return ConditionSpec(name, None, None, "s", text, between, float(gap))
