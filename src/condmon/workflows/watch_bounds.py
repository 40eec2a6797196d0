"""What a watcher may hold: units admitted, and samples held in bytes.

Every limit is ``[stream]`` of ``condmon/data/limits.toml`` (where each number's
reason is given). Past a limit a message is refused and counted; the first
refusal of each kind is said at once, later ones at most every 10 s with their
count, so a flood cannot flood the log too.
"""

from __future__ import annotations

import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from condmon.errors import ConfigError, DataError
from condmon.io.stream import Chunk, StreamLimits

__all__ = ["Bounds", "Refused", "nbytes", "unit_pattern", "pieces", "by_length"]

SAY_EVERY = 10.0  # [s] between two lines about the same kind of refusal
#: Samples of a plant unit's chunk stepped at once: a longer chunk (up to
#: ``[stream] max_chunk_samples``) is stepped in pieces, so a stop is never more
#: than one piece away (about 10 s of CPU for one unit).
PIECE = 10_000
#: Unit-samples one vectorised step of many units may hold: units of one round
#: are stepped together only while padding every chunk to the longest stays
#: within it (about 100 MB of inputs and outputs for the HST) and wastes at most
#: half the work.
CELLS = 2_000_000


def nbytes(columns: Mapping[str, np.ndarray]) -> int:
    """Bytes a chunk's columns hold."""
    return int(sum(a.nbytes for a in columns.values()))


def pieces(chunk: Chunk, most: int | None = None) -> list[Chunk]:
    """``chunk`` cut into pieces of at most ``most`` samples, in order; the last
    piece carries its journal row (done with once the whole chunk is).

    Example
    -------
    >>> c = Chunk("U1", {"t": np.arange(5.0)}, ref=7)
    >>> [(len(p.columns["t"]), p.ref) for p in pieces(c, 2)]
    [(2, None), (2, None), (1, 7)]
    """
    most = most or PIECE
    n = chunk.samples
    if n <= most:
        return [chunk]
    cuts = list(range(0, n, most))
    return [Chunk(chunk.unit, {c: v[k:k + most] for c, v in chunk.columns.items()},
                  chunk.end and k == cuts[-1], chunk.ref if k == cuts[-1] else None)
            for k in cuts]


def by_length(batch: Sequence[Chunk], cells: int = CELLS) -> list[list[Chunk]]:
    """One round's chunks (one a unit) in groups stepped together: by length,
    a group's padded size (its longest chunk times its units) within ``cells``
    and at most twice its samples.

    Example
    -------
    >>> short = [Chunk(f"U{i}", {"t": np.zeros(10)}) for i in range(3)]
    >>> long = Chunk("L", {"t": np.zeros(1000)})
    >>> [[c.unit for c in g] for g in by_length([long, *short])]
    [['U0', 'U1', 'U2'], ['L']]
    """
    groups: list[list[Chunk]] = []
    for chunk in sorted(batch, key=lambda c: c.samples):
        group = groups[-1] if groups else None
        if group is not None:
            padded = chunk.samples * (len(group) + 1)
            if padded <= cells and padded <= 2 * (sum(c.samples for c in group)
                                                  + chunk.samples):
                group.append(chunk)
                continue
        groups.append([chunk])
    return groups


def unit_pattern(text: str | None) -> re.Pattern[str] | None:
    """``--units PATTERN``: a regular expression a unit name must match whole.

    Example
    -------
    >>> bool(unit_pattern("HST-[0-9]+").fullmatch("HST-12"))
    True
    """
    if text is None:
        return None
    try:
        return re.compile(text)
    except re.error as exc:
        raise ConfigError(f"--units {text!r}: not a regular expression ({exc})") from None


@dataclass
class Bounds:
    """Units admitted and bytes held, per unit and in all.

    Parameters
    ----------
    limits : StreamLimits
    units : re.Pattern, optional
        Only unit names matching it whole are followed.
    """

    limits: StreamLimits = field(default_factory=StreamLimits.shipped)
    units: re.Pattern[str] | None = None
    held: dict[str, int] = field(default_factory=dict)
    total: int = 0
    _admitted: set[str] = field(default_factory=set)
    _said: dict[str, tuple[float, int]] = field(default_factory=dict)

    def admit(self, unit: str) -> None:
        """Follow ``unit``, or refuse it: not matching ``--units``, or one unit
        past ``max_units``."""
        if unit in self._admitted:
            return
        if self.units is not None and not self.units.fullmatch(unit):
            raise self.refusal("units", f"unit {unit!r} does not match --units "
                               f"{self.units.pattern!r}; its messages are refused")
        if len(self._admitted) >= self.limits.max_units:
            raise self.refusal("max_units", f"unit {unit!r} is new and the watcher follows "
                               f"{self.limits.max_units} units already ([stream] max_units); "
                               "its messages are refused")
        self._admitted.add(unit)

    def take(self, unit: str, size: int) -> None:
        """Hold ``size`` more bytes for ``unit``, or refuse: past ``held_bytes``
        in all."""
        if self.total + size > self.limits.held_bytes:
            raise self.refusal("held_bytes", f"unit {unit!r}: chunk refused, all units hold "
                               f"{self.total} bytes of samples already ([stream] held_bytes = "
                               f"{self.limits.held_bytes})")
        self.held[unit] = self.held.get(unit, 0) + size
        self.total += size

    def give(self, unit: str, size: int) -> None:
        """Release ``size`` bytes of ``unit``."""
        left = self.held.get(unit, 0) - size
        self.total -= min(size, self.held.get(unit, 0))
        if left > 0:
            self.held[unit] = left
        else:
            self.held.pop(unit, None)

    def over_unit(self, unit: str, size: int = 0) -> bool:
        """Whether ``unit`` would hold more than ``unit_bytes`` with ``size`` more."""
        return self.held.get(unit, 0) + size > self.limits.unit_bytes

    def refusal(self, kind: str, line: str) -> Refused:
        """The error for a refusal past a limit: to be said at once if it is the
        first of its kind for 10 s (with the count of those not said since)."""
        now = time.monotonic()
        last, count = self._said.get(kind, (-np.inf, 0))
        if now - last >= SAY_EVERY:
            more = f" ({count} more of this kind since the last line)" if count else ""
            self._said[kind] = (now, 0)
            return Refused(line + more, say=True)
        self._said[kind] = (last, count + 1)
        return Refused(line, say=False)


class Refused(DataError):
    """A message refused past a limit; ``say`` is false for one counted only
    (a line about its kind was said less than 10 s ago)."""

    def __init__(self, message: str, say: bool = True) -> None:
        super().__init__(message)
        self.say = say
