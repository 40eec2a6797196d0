"""File names of report pages: one of its own for every unit name."""

from __future__ import annotations

import hashlib
import re
import unicodedata

__all__ = ["page_name", "INDEX"]

#: The fleet index's file name (without suffix); no unit page takes it.
INDEX = "index"

#: Longest slug kept before the hash. [characters]
_KEEP = 80

#: Names a file cannot have on some systems, or that the report itself uses.
_RESERVED = frozenset({INDEX, "con", "prn", "aux", "nul",
                       *(f"com{i}" for i in range(10)), *(f"lpt{i}" for i in range(10))})


def page_name(unit: str) -> str:
    """A file name (without suffix) of its own for every unit name.

    Letters, digits, ``-``, ``_`` and ``.`` are kept, accented letters lose
    their accents and any other run of characters becomes one ``_``; when the
    slug is lossy (anything changed), the name is long, or it is one a file
    cannot have (``index``, which the fleet index uses, or a device name such
    as ``CON``), a short hash of the exact name is added. So ``EMA/7`` and
    ``EMA:7`` get different files, and every name, with the suffixes the
    report adds, stays far below 255 bytes.

    Parameters
    ----------
    unit : str
        The unit's name in the history.

    Returns
    -------
    str
        ASCII letters, digits, ``-``, ``_`` and ``.`` only, at most 91 characters.

    Examples
    --------
    >>> page_name("EMA-7")
    'EMA-7'
    >>> page_name("EMA/7") != page_name("EMA:7")
    True
    >>> page_name("index") != "index"
    True
    >>> page_name("Ölpumpe <2>")[:-11]
    'Olpumpe_2_'

    """
    ascii_ = unicodedata.normalize("NFKD", unit).encode("ascii", "ignore").decode("ascii")
    slug = re.sub(r"[^A-Za-z0-9._-]+", "_", ascii_).strip(".") or "unit"
    if slug == unit and len(unit) <= _KEEP and slug.split(".")[0].lower() not in _RESERVED:
        return unit
    digest = hashlib.sha256(unit.encode("utf-8")).hexdigest()[:10]
    return f"{slug[:_KEEP]}-{digest}"
