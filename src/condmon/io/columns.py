"""A plain CSV record read without pandas: the start-up path of one estimate.

Most records a rig writes are plain: comma-separated, a header of distinct
names, then rows of decimal numbers and nothing else. :func:`read_plain_csv`
reads such a file into :class:`Columns` (float64 arrays under the header's
names) with the standard library and numpy, so ``condmon estimate`` does not
import pandas. Anything else — another separator or decimal mark, quotes,
blank or ragged lines, a value that is not a plain decimal number (a date, an
empty field, ``nan``), another suffix — gives None, and the caller reads the
file with :func:`condmon.io.readers.read_record`, which says what is wrong in
its own words. The numbers are the ones pandas reads (both round correctly).
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import DataError
from condmon.io.size import check_record_size

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Columns", "read_plain_csv", "column_values", "column_matrix", "as_columns"]

FloatArray = NDArray[np.float64]

#: A plain decimal number: no spaces, no digit separators, no nan/inf.
_NUMBER = r"-?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
#: An integer of more digits may not fit an int64: left to pandas' rules.
_LONGEST_INTEGER = 18


class Columns:
    """A record's columns as float64 arrays, in file order, with ``attrs``
    (``source``: the file), as :func:`read_plain_csv` returns them.

    Indexing by a column's name gives its array; ``columns`` lists the names
    and ``len()`` is the row count, as for the DataFrame the readers return.
    """

    def __init__(self, values: Mapping[str, FloatArray], attrs: Mapping[str, Any] | None = None
                 ) -> None:
        self._values = dict(values)
        self.attrs: dict[str, Any] = dict(attrs or {})

    @property
    def columns(self) -> list[str]:
        """The column names, in file order."""
        return list(self._values)

    def __getitem__(self, name: str) -> FloatArray:
        return self._values[name]

    def __contains__(self, name: object) -> bool:
        return name in self._values

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return int(next(iter(self._values.values())).size) if self._values else 0

    def to_frame(self) -> pd.DataFrame:
        """The same record as a pandas DataFrame (``attrs`` copied)."""
        import pandas as pd

        frame = pd.DataFrame(self._values)
        frame.attrs.update(self.attrs)
        return frame


#: Most values a frame is converted in one piece (:func:`as_columns`): a frame
#: pandas keeps in several blocks is copied whole by that conversion, so a
#: long record is left to the column-by-column path (8 MB at most copied).
WHOLE_FRAME_VALUES = 1 << 20


def as_columns(frame: pd.DataFrame | Columns) -> pd.DataFrame | Columns:
    """A DataFrame of float64 columns as :class:`Columns`, in one conversion.

    Taking a column from a pandas frame costs about 25 µs (a new Series,
    its ``attrs`` deep-copied); the whole frame's values cost 3 µs and
    their columns are views of it. A frame with another dtype, repeated or
    non-string names, or more than :data:`WHOLE_FRAME_VALUES` values is
    returned as it is (its columns are converted and checked one by one).

    Example
    -------
    >>> import pandas as pd
    >>> rec = as_columns(pd.DataFrame({"t": [0.0, 0.1], "V": [1.0, 2.0]}))
    >>> type(rec).__name__, rec["V"].tolist()
    ('Columns', [1.0, 2.0])
    """
    if isinstance(frame, Columns):
        return frame
    rows, width = frame.shape
    if rows * width > WHOLE_FRAME_VALUES:
        return frame
    # the common dtype of the columns tells whether every one is float64 (or
    # an integer one beside them, converted exactly below 2**53, as the column
    # by column path converts it) without the Series ``frame.dtypes`` builds
    values = frame.to_numpy()
    if values.dtype != np.float64:
        return frame
    names = [n for n in frame.columns.to_list() if isinstance(n, str)]
    if len(names) != width or len(set(names)) != width:
        return frame
    return Columns({n: values[:, i] for i, n in enumerate(names)},
                   {str(k): v for k, v in frame.attrs.items()})


def column_values(frame: Any, name: str) -> FloatArray:
    """A column of a record (a DataFrame or :class:`Columns`) as float64,
    missing values as NaN."""
    if isinstance(frame, Columns):
        return frame[name]
    return np.asarray(frame[name].to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)


def column_matrix(frame: Any, names: Sequence[str]) -> FloatArray:
    """Columns of a record (a DataFrame or :class:`Columns`) side by side as
    float64, shape (N, len(names))."""
    if isinstance(frame, Columns):
        return np.column_stack([frame[n] for n in names])
    return np.asarray(frame[list(names)].to_numpy(dtype=np.float64), dtype=np.float64)


def read_plain_csv(path: str | Path, columns: Mapping[str, str] | None = None
                   ) -> Columns | None:
    """Read a plain CSV record, or None when the file is not plain.

    Parameters
    ----------
    path : str or Path
        A ``.csv`` file.
    columns : mapping, optional
        ``{canonical: column in the file}``, as for
        :func:`~condmon.io.readers.read_record`.

    Returns
    -------
    Columns or None
        The columns under canonical names, ``attrs["source"]`` the path; None
        for a file :func:`~condmon.io.readers.read_record` must read (or
        refuse): not plain, not UTF-8, too big, a mapping it does not satisfy.

    Example
    -------
    >>> import tempfile
    >>> d = tempfile.TemporaryDirectory()
    >>> p = Path(d.name) / "rig.csv"
    >>> _ = p.write_text("t,volts\\n0.0,1.5\\n0.001,2.5\\n")
    >>> rec = read_plain_csv(p, {"V": "volts"})
    >>> rec.columns, rec["V"].tolist()
    (['t', 'V'], [1.5, 2.5])
    >>> _ = p.write_text("t;V\\n0,0;1,5\\n")
    >>> read_plain_csv(p) is None
    True
    >>> d.cleanup()
    """
    p = Path(path)
    mapping = dict(columns or {})
    if (p.suffix.lower() != ".csv" or not p.is_file() or p.stat().st_size == 0
            or len(set(mapping.values())) < len(mapping)):
        return None
    try:
        check_record_size(p, ".csv")
        text = p.read_bytes().decode("utf-8-sig")
    except (DataError, OSError, UnicodeDecodeError, MemoryError):
        return None
    values = _parse(text)
    if values is None or any(f not in values for f in mapping.values()):
        return None
    if mapping:  # as the readers map: a mapped column replaces one of the canonical name
        mapped = set(mapping.values())
        back = {v: k for k, v in mapping.items()}
        values = {back.get(n, n): a for n, a in values.items()
                  if n in mapped or n not in mapping}
    return Columns(values, {"source": str(p)})


def _parse(text: str) -> dict[str, FloatArray] | None:
    """The columns of a plain CSV text, or None."""
    if '"' in text or "\t" in text or ";" in text:
        return None
    lines = text.splitlines()
    if len(lines) < 2 or not lines[0]:
        return None
    names = [h.strip() for h in lines[0].split(",")]
    width = len(names)
    number = re.compile(_NUMBER)
    if (width < 2 or len(set(names)) < width
            or any(not n or number.fullmatch(n) for n in names)):
        return None
    row = re.compile(",".join([_NUMBER] * width))
    body = lines[1:]
    if not all(row.fullmatch(line) for line in body):
        return None
    fields = ",".join(body).split(",")
    if any(len(f) > _LONGEST_INTEGER and f.lstrip("-").isdigit() for f in fields):
        return None
    table = np.array([float(f) for f in fields], dtype=np.float64).reshape(len(body), width)
    return {n: np.ascontiguousarray(table[:, i]) for i, n in enumerate(names)}
