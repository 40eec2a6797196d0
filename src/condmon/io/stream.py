"""Messages of a stream: one chunk of one unit's record per message.

The contract (README, "Live monitoring"): a message on the topic
``condmon/<unit>/samples`` is a JSON object of equal-length columns, ``t`` in
seconds and any record columns, e.g. ``{"t": [0.0, 0.01], "Ps": [...], ...}``.
``{"end": true}`` (alone, or beside the last columns) closes a unit's test
record for a model that estimates from whole tests. Anything else is refused
with one line naming the unit and the topic: the stream goes on.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError, DataError
from condmon.io.config import shipped_limits

__all__ = ["Chunk", "StreamLimits", "SAMPLES_TOPIC", "STATUS_TOPIC", "unit_of_topic",
           "parse_chunk", "parse_broker"]

FloatArray = NDArray[np.float64]

#: Where a unit's samples arrive, and where its status is published.
SAMPLES_TOPIC = "condmon/{unit}/samples"
STATUS_TOPIC = "condmon/{unit}/status"
_TOPIC = re.compile(r"^condmon/([A-Za-z0-9][A-Za-z0-9._-]{0,63})/samples$")


@dataclass(frozen=True)
class StreamLimits:
    """Bounds on a stream (``[stream]`` of ``condmon/data/limits.toml``).

    Attributes
    ----------
    max_message_bytes : int
        One message's payload. [bytes]
    max_chunk_samples : int
        Samples of one chunk.
    queue : int
        Messages waiting to be handled.
    events : int
        Events waiting to be published or posted.
    stale_after : float
        A unit silent this long is shown stale on the live page. [s]
    keep : float
        Seconds of a plant unit's stream kept before a detection. [s]
    max_test_samples : int
        Samples of one estimation-model unit's test before its ``end``.
    queue_bytes : int
        Payloads waiting to be journaled and handled. [bytes]
    unit_bytes : int
        Samples one unit holds: its open test or its kept window. [bytes]
    held_bytes : int
        Samples all units hold together. [bytes]
    max_units : int
        Units one watcher follows; a new unit name past it is refused.
    """

    max_message_bytes: int = 8_000_000
    max_chunk_samples: int = 100_000
    queue: int = 10_000
    events: int = 1_000
    stale_after: float = 30.0
    keep: float = 60.0
    max_test_samples: int = 2_000_000
    queue_bytes: int = 128_000_000
    unit_bytes: int = 48_000_000
    held_bytes: int = 384_000_000
    max_units: int = 10_000

    @classmethod
    def shipped(cls) -> StreamLimits:
        """The shipped limits."""
        return shipped_limits("stream", cls)


@dataclass(frozen=True)
class Chunk:
    """One message: a unit's samples, and whether its test record ends here.

    Attributes
    ----------
    unit : str
    columns : dict of str to ndarray
        Equal-length float64 columns, ``t`` among them (empty for a bare end). [SI]
    end : bool
        The message closes the unit's test record.
    ref : int or None
        The message's row in the watcher's journal (:mod:`condmon.store.journal`),
        if it was journaled.
    """

    unit: str
    columns: dict[str, FloatArray] = field(default_factory=dict)
    end: bool = False
    ref: int | None = None

    @property
    def samples(self) -> int:
        """Number of samples."""
        return len(self.columns["t"]) if "t" in self.columns else 0


def unit_of_topic(topic: str) -> str:
    """The unit a samples topic names.

    Example
    -------
    >>> unit_of_topic("condmon/HST-7/samples")
    'HST-7'
    """
    m = _TOPIC.match(topic)
    if m is None:
        raise DataError(f"topic {topic!r} is not condmon/<unit>/samples (a unit: letters, "
                        "digits, '.', '_', '-', up to 64)")
    return m.group(1)


def parse_chunk(topic: str, payload: bytes | str, limits: StreamLimits | None = None) -> Chunk:
    """Validate one message.

    Raises
    ------
    DataError
        One line naming the unit and topic: not JSON, not an object, a column
        that is not a list of finite numbers, columns of unequal length, no
        ``t`` or ``t`` not increasing, too large.

    Example
    -------
    >>> c = parse_chunk("condmon/U1/samples", '{"t": [0, 0.01], "Ps": [1e5, 1.1e5]}')
    >>> c.unit, c.samples, c.end
    ('U1', 2, False)
    >>> parse_chunk("condmon/U1/samples", '{"t": [0, 0.01], "Ps": [1e5]}')
    Traceback (most recent call last):
    ...
    condmon.errors.DataError: unit 'U1' (topic condmon/U1/samples): columns of unequal length (t: 2, Ps: 1)
    """
    lim = limits or StreamLimits.shipped()
    unit = unit_of_topic(topic)
    where = f"unit {unit!r} (topic {topic})"
    if len(payload) > lim.max_message_bytes:
        raise DataError(f"{where}: message of {len(payload)} bytes, beyond the limit of "
                        f"{lim.max_message_bytes} ([stream] max_message_bytes)")
    try:
        doc = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"{where}: not JSON ({str(exc).splitlines()[0][:80]})") from None
    except RecursionError:
        raise DataError(f"{where}: not a message of columns (JSON nested too deep)") from None
    if not isinstance(doc, dict):
        raise DataError(f"{where}: a message is a JSON object of columns, not a "
                        f"{type(doc).__name__}")
    end = doc.pop("end", False)
    if end not in (True, False):
        raise DataError(f"{where}: 'end' must be true or false, not {end!r}")
    if not doc:
        if end:
            return Chunk(unit, {}, True)
        raise DataError(f"{where}: the message holds no column")
    cols: dict[str, FloatArray] = {}
    for name, values in doc.items():
        if not isinstance(values, list) or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in values):
            raise DataError(f"{where}: column {name!r} is not a list of numbers")
        if len(values) > lim.max_chunk_samples:
            raise DataError(f"{where}: column {name!r} has {len(values)} samples, beyond the "
                            f"limit of {lim.max_chunk_samples} ([stream] max_chunk_samples)")
        try:
            arr = np.asarray(values, dtype=np.float64)
        except OverflowError:  # an integer beyond float64 (1e309 written out in digits)
            k = next(i for i, v in enumerate(values) if abs(v) > 1.7976931348623157e308)
            raise DataError(f"{where}: column {name!r} has a value beyond float64 at sample "
                            f"{k}") from None
        if not np.all(np.isfinite(arr)):
            k = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise DataError(f"{where}: column {name!r} has a non-finite value at sample {k}")
        cols[str(name)] = arr
    if "t" not in cols:
        raise DataError(f"{where}: no column 't' (time [s]); columns: {', '.join(cols)}")
    lengths = {k: len(v) for k, v in cols.items()}
    if len(set(lengths.values())) > 1:
        raise DataError(f"{where}: columns of unequal length ("
                        + ", ".join(f"{k}: {n}" for k, n in lengths.items()) + ")")
    if not lengths["t"]:
        if end:
            return Chunk(unit, {}, True)
        raise DataError(f"{where}: the columns hold no sample (send {{\"end\": true}} alone "
                        "to close a test)")
    t = cols["t"]
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        k = int(np.flatnonzero(~(np.diff(t) > 0))[0])
        raise DataError(f"{where}: 't' does not increase at sample {k + 1} "
                        f"({t[k]:g} then {t[k + 1]:g} s)")
    if len(t) and not math.isfinite(float(t[-1])):
        raise DataError(f"{where}: 't' is not finite")
    return Chunk(unit, cols, bool(end))


def parse_broker(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (port 1883 when left out).

    Example
    -------
    >>> parse_broker("127.0.0.1:18830"), parse_broker("broker.local")
    (('127.0.0.1', 18830), ('broker.local', 1883))
    """
    host, _, port = text.rpartition(":") if ":" in text else (text, "", "1883")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 < number < 65536:
        raise ConfigError(f"--mqtt {text!r}: give HOST:PORT (e.g. localhost:1883)")
    return host, number
