"""How big a record file is, told before it is loaded.

A small file can describe a huge record (a Parquet file of 250 M zeros is a
few MB; a sparse CSV of 2 GB holds nothing but takes 2 GB to parse). The size
is read from what the format says of itself wherever it says it — Parquet
metadata, MATLAB and HDF5 variable shapes, TDMS channel lengths — and, for
text, from the file's size and a streamed count of its lines. A record beyond
the limits (``[records]`` of ``condmon/data/limits.toml``: samples and bytes,
raised with ``CONDMON_MAX_SAMPLES`` and ``CONDMON_MAX_RECORD_BYTES``) is refused
with one line naming the limit and how to raise it; nothing is loaded.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from condmon.errors import DataError

__all__ = ["RecordLimits", "record_limits", "check_record_size", "record_samples"]

#: Bytes read at a time when counting the lines of a text file.
CHUNK = 1 << 22


@dataclass(frozen=True)
class RecordLimits:
    """Largest record condmon loads.

    Attributes
    ----------
    max_samples : int
        Values in a record: rows times columns of the numbers it holds.
    max_bytes : int
        Size of a text record's file. [bytes]
    """

    max_samples: int = 10_000_000
    max_bytes: int = 1_000_000_000


def record_limits() -> RecordLimits:
    """The limits in force: ``CONDMON_MAX_SAMPLES`` and ``CONDMON_MAX_RECORD_BYTES``
    when set, else the shipped ``[records]`` table.

    Example
    -------
    >>> record_limits().max_samples > 1_000_000
    True
    """
    from condmon.io.config import shipped_limits

    shipped = shipped_limits("records", RecordLimits)
    env = {"CONDMON_MAX_SAMPLES": shipped.max_samples,
           "CONDMON_MAX_RECORD_BYTES": shipped.max_bytes}
    for name in env:
        text = os.environ.get(name, "").strip()
        if text:
            try:
                env[name] = int(float(text))
            except ValueError:
                raise DataError(f"{name}={text!r} is not a number") from None
    return RecordLimits(env["CONDMON_MAX_SAMPLES"], env["CONDMON_MAX_RECORD_BYTES"])


def _refuse(path: Path, what: str, limit: str) -> DataError:
    return DataError(f"{path}: {what}, beyond the limit of {limit} ([records] of "
                     "condmon/data/limits.toml; raise it with CONDMON_MAX_SAMPLES or "
                     "CONDMON_MAX_RECORD_BYTES); nothing was loaded")


def _text_lines(path: Path, stop: int) -> int:
    """Lines of a text file, counted in chunks; stops counting past ``stop``."""
    n = 0
    with path.open("rb") as fh:
        while chunk := fh.read(CHUNK):
            n += chunk.count(b"\n")
            if n > stop:
                break
    return n


def _header_width(path: Path) -> int:
    """Fields of a text file's first line (its largest count of , ; or tab)."""
    with path.open("rb") as fh:
        first = fh.readline(1 << 20)
    return max(1, *(first.count(sep) + 1 for sep in (b",", b";", b"\t")))


def record_samples(path: Path, suffix: str) -> int | None:
    """Values a record file holds, read from its metadata without loading it
    (text files: the lines counted times the header's fields); None when the
    format does not say."""
    if suffix in (".parquet", ".pq"):
        import pyarrow.parquet as pq

        meta = pq.ParquetFile(path).metadata
        return int(meta.num_rows) * max(1, int(meta.num_columns))
    if suffix == ".mat":
        return _mat_samples(path)
    if suffix == ".tdms":
        from nptdms import TdmsFile

        meta = TdmsFile.read_metadata(path)
        return sum(int(len(c)) for g in meta.groups() for c in g.channels())
    if suffix in (".csv", ".txt", ".tsv"):
        lim = record_limits()
        width = _header_width(path)
        return _text_lines(path, lim.max_samples // width + 1) * width
    return None


def _mat_samples(path: Path) -> int:
    from condmon.io.matlab import is_hdf5

    if is_hdf5(path):
        import h5py

        total = 0

        def visit(_: str, obj: Any) -> None:
            nonlocal total
            if isinstance(obj, h5py.Dataset):
                size = 1
                for d in obj.shape:
                    size *= int(d)
                total += size

        with h5py.File(path, "r") as f:
            f.visititems(visit)
        return total
    import scipy.io

    total = 0
    for _, shape, _ in scipy.io.whosmat(str(path)):
        size = 1
        for d in shape:
            size *= int(d)
        total += size
    return total


def check_record_size(path: Path, suffix: str) -> None:
    """Refuse a record file beyond the limits before anything is loaded.

    Raises
    ------
    DataError
        One line naming the file, its size and the limit.

    Example
    -------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "r.csv"
    >>> _ = p.write_text("t,V\\n0,1\\n")
    >>> check_record_size(p, ".csv")
    """
    lim = record_limits()
    if suffix in (".csv", ".txt", ".tsv"):
        size = path.stat().st_size
        if size > lim.max_bytes:
            raise _refuse(path, f"{size / 1e6:.0f} MB of text", f"{lim.max_bytes / 1e6:.0f} MB")
    try:
        n = record_samples(path, suffix)
    except DataError:
        raise
    except Exception:  # noqa: BLE001 - unreadable metadata: the reader says why
        return
    if n is not None and n > lim.max_samples:
        raise _refuse(path, f"{n:,} values", f"{lim.max_samples:,} values")
