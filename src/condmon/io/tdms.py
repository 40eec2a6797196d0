"""LabVIEW TDMS records, through npTDMS.

Each numeric channel of the record's length becomes a column named like the
channel; a channel name found in two groups is written ``group/channel`` for
both. When the file has no time channel (a channel ``t``, the channel the
column mapping names for ``t``, or a channel of time stamps), the time base is
built from the channels' waveform properties: ``t = wf_start_offset + k *
wf_increment`` [s], with ``wf_start_time`` kept as the absolute start.
"""

from __future__ import annotations

import logging
import warnings
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from condmon.errors import DataError, DataWarning
from condmon.io.raw import RawRecord, select_vectors

__all__ = ["read_tdms"]

#: LabVIEW's zero time stamp: a ``wf_start_time`` left unset.
_LABVIEW_EPOCH = np.datetime64("1904-01-01T00:00:00")


def read_tdms(path: Path, time_column: str | None = None) -> RawRecord:
    """Read a TDMS record: channels as columns, the time base from the waveform.

    Parameters
    ----------
    path : Path
        A ``.tdms`` file.
    time_column : str, optional
        The channel the column mapping names for ``t``: when given, no time
        base is built from the waveform properties.

    Returns
    -------
    RawRecord
        ``frame`` with ``t`` [s] first when it was built, then one column per
        channel; ``start_time`` from ``wf_start_time`` when set.

    Raises
    ------
    DataError
        No numeric channel, or channels whose ``wf_increment`` disagree.

    Example
    -------
    >>> import tempfile
    >>> from nptdms import ChannelObject, TdmsWriter
    >>> d = tempfile.TemporaryDirectory()
    >>> p = Path(d.name) / "rig.tdms"
    >>> with TdmsWriter(p) as w:
    ...     w.write_segment([ChannelObject("rig", "volts", np.array([1.0, 2.0, 3.0]),
    ...                                    {"wf_increment": 0.5})])
    >>> read_tdms(p).frame.to_dict("list")
    {'t': [0.0, 0.5, 1.0], 'volts': [1.0, 2.0, 3.0]}
    >>> d.cleanup()
    """
    from nptdms import TdmsFile

    with _npTDMS_log() as messages:
        tdms = TdmsFile.read(path)
    channels = [(group.name, channel) for group in tdms.groups() for channel in group.channels()]
    lengths = {len(channel) for _, channel in channels}
    if messages and len(lengths) > 1:  # the file ends inside a segment: channels cut short
        raise DataError(f"{path}: the file is truncated: its channels hold {min(lengths)} to "
                        f"{max(lengths)} samples (npTDMS: {'; '.join(dict.fromkeys(messages))})")
    if messages:
        warnings.warn(f"{path}: {'; '.join(dict.fromkeys(messages))} (npTDMS; an incomplete "
                      "file?)", DataWarning, stacklevel=4)
    count = Counter(channel.name for _, channel in channels)
    items: dict[str, np.ndarray[Any, Any]] = {}
    props: dict[str, dict[str, Any]] = {}
    for group, channel in channels:
        label = f"{group}/{channel.name}" if count[channel.name] > 1 else str(channel.name)
        items[label] = np.asarray(channel[:])
        props[label] = dict(channel.properties)
    columns, _, ignored = select_vectors(items, path, "channel", constants=False)
    frame = pd.DataFrame(columns)
    has_time = ("t" in columns or (time_column is not None and time_column in columns)
                or any(v.dtype.kind == "M" for v in columns.values()))
    start_time = None
    if not has_time:
        base = _time_base({k: props[k] for k in columns}, path)
        if base is not None:
            offset, increment, start = base
            frame.insert(0, "t", offset + increment * np.arange(len(frame), dtype=np.float64))
            start_time = start
    return RawRecord(frame, start_time=start_time, ignored=ignored)


class _Collect(logging.Handler):
    def __init__(self, messages: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.messages = messages

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def _npTDMS_log() -> Iterator[list[str]]:
    """npTDMS's log lines (a truncated file ...) collected instead of printed."""
    messages: list[str] = []
    try:
        from nptdms.log import log_manager
        console, loggers = log_manager.console_handler, list(log_manager.loggers.values())
    except (ImportError, AttributeError):  # another npTDMS: its lines go where it sends them
        yield messages
        return
    handler, level = _Collect(messages), console.level
    console.setLevel(logging.CRITICAL + 1)
    for log in loggers:
        log.addHandler(handler)
    try:
        yield messages
    finally:
        console.setLevel(level)
        for log in loggers:
            log.removeHandler(handler)


def _time_base(props: dict[str, dict[str, Any]], path: Path
               ) -> tuple[float, float, str | None] | None:
    """(wf_start_offset [s], wf_increment [s], wf_start_time) shared by the channels."""
    increments = {k: float(p["wf_increment"]) for k, p in props.items() if "wf_increment" in p}
    if not increments:
        return None
    (first, inc), *rest = increments.items()
    for name, other in rest:
        if not np.isclose(other, inc, rtol=1e-9, atol=0.0):
            raise DataError(f"{path}: channels {first!r} (wf_increment {inc:.6g} s) and "
                            f"{name!r} ({other:.6g} s) are sampled at different rates; "
                            "map t to a time channel or read one group")
    if not inc > 0:
        raise DataError(f"{path}: channel {first!r} has wf_increment {inc:.6g} s; "
                        "a time base needs a positive sample interval")
    p = props[first]
    offset = float(p.get("wf_start_offset", 0.0))
    start = p.get("wf_start_time")
    start_iso = None
    if start is not None:
        stamp = np.datetime64(start)
        if stamp != _LABVIEW_EPOCH:
            start_iso = pd.Timestamp(stamp).isoformat()
    return offset, inc, start_iso
