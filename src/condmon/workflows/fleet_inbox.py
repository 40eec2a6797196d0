"""Finding a fleet's records: an inbox folder (a folder per unit) or a manifest.

This module holds what :func:`condmon.workflows.fleet.run_fleet` is offered:
:class:`FleetRecord` (a record file, its unit and what the manifest or the unit
folder's ``unit.toml`` says of it), :func:`inbox_records` (``INBOX/UNIT/record
files``), :func:`read_manifest` (a CSV or TOML list of records) and the
file-name order records are run in when they carry no date. It reads folders
and manifests only, never a record's data.
"""

from __future__ import annotations

import csv
import re
import tomllib
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from condmon.errors import ConfigError, DataError
from condmon.io.dates import parse_date
from condmon.io.readers import READABLE_SUFFIXES

__all__ = ["FleetRecord", "inbox_records", "read_manifest"]

#: Name of a unit folder's optional declaration (``model = "..."``).
UNIT_FILE = "unit.toml"


@dataclass(frozen=True)
class FleetRecord:
    """One record offered to the fleet run.

    Attributes
    ----------
    unit : str
        The unit (machine) it belongs to.
    path : Path
        The record file.
    model : str or None
        The model the manifest names for the unit (it must match the unit's
        stored model), else None.
    fallback_model : str or None
        The model of the unit folder's ``unit.toml``, used when the unit has no
        history yet and the manifest names none.
    test_date : datetime or None
        When the test was run (the manifest's ``date``, UTC); None: the
        record's own date, if its metadata has one.
    error : str or None
        Why the record is refused before it is read (a manifest row's bad date).
    """

    unit: str
    path: Path
    model: str | None = None
    fallback_model: str | None = None
    test_date: datetime | None = None
    error: str | None = None


def _one_line(exc: BaseException | str) -> str:
    return " ".join(str(exc).split()) or (type(exc).__name__ if isinstance(exc, BaseException)
                                          else "")


def _natural(text: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key of a name with its numbers compared as numbers (rec-2 < rec-10)."""
    return tuple((0, int(part)) if part.isdigit() else (1, part)
                 for part in re.split(r"(\d+)", text) if part)


def _name_key(path: Path) -> tuple[Any, ...]:
    """File-name order: numbers as numbers, a name before its longer variants
    (``rec-2.csv`` < ``rec-2-copy.csv`` < ``rec-10.csv``)."""
    return (_natural(str(path.with_suffix(""))), path.suffix)


def _is_record(path: Path) -> bool:
    return (path.is_file() and not path.name.startswith(".")
            and path.suffix.lower() in READABLE_SUFFIXES)


def _unit_file_model(folder: Path) -> tuple[str | None, str | None]:
    """``(model, error)`` of ``folder/unit.toml`` (both None without one)."""
    path = folder / UNIT_FILE
    if not path.is_file():
        return None, None
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        return None, f"{path}: cannot read: {_one_line(exc)}"
    model = doc.get("model")
    if not isinstance(model, str) or not model.strip():
        return None, f"{path}: needs model = \"NAME or declaration.toml\""
    model = model.strip()
    if model.lower().endswith(".toml") and not Path(model).is_absolute():
        model = str(folder / model)
    return model, None


def inbox_records(inbox: str | Path) -> list[FleetRecord]:
    """The records of an inbox folder: ``INBOX/UNIT/...`` (a folder per unit).

    Every file under a unit's folder (sub-folders too) with a record suffix
    (:data:`condmon.io.readers.READABLE_SUFFIXES`) is a record of that unit;
    other files and hidden ones are ignored. ``INBOX/UNIT/unit.toml`` may name
    the unit's model (``model = "dc-motor-coulomb"`` or a declaration file,
    relative to the folder), used while the unit has no history. A record file
    directly in the inbox (in no unit's folder) is refused.

    Raises
    ------
    ConfigError
        ``inbox`` is not a folder.

    Example
    -------
    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> for name in ("EMA-1/rec-10.csv", "EMA-1/rec-2.csv", "EMA-1/notes.md"):
    ...     (root / name).parent.mkdir(exist_ok=True)
    ...     _ = (root / name).write_text("t\\n")
    >>> [r.path.name for r in inbox_records(root)]
    ['rec-2.csv', 'rec-10.csv']
    """
    root = Path(inbox)
    if not root.is_dir():
        raise ConfigError(f"{root}: not a folder; the inbox holds a folder per unit "
                          "(INBOX/UNIT/record files)")
    records: list[FleetRecord] = []
    for entry in sorted(root.iterdir(), key=lambda p: _natural(p.name)):
        if entry.name.startswith("."):
            continue
        if entry.is_dir():
            model, error = _unit_file_model(entry)
            files = sorted((p for p in entry.rglob("*") if _is_record(p)),
                           key=lambda p: _name_key(p.relative_to(entry)))
            records += [FleetRecord(entry.name, p, fallback_model=model, error=error)
                        for p in files]
        elif _is_record(entry):
            records.append(FleetRecord("", entry, error=f"{entry}: not in a unit's folder "
                                       "(INBOX/UNIT/record files)"))
    return records


MANIFEST_COLUMNS = ("unit", "file", "model", "date")


def read_manifest(manifest: str | Path) -> list[FleetRecord]:
    """The records listed in a manifest (CSV or TOML).

    A CSV manifest has a header with the columns ``unit`` and ``file``, and
    optionally ``model`` and ``date``; a TOML manifest lists ``[[records]]``
    tables with the same keys. A relative ``file`` (and a relative model
    declaration ``.toml``) is resolved against the manifest's folder. A unit's
    rows must name one model (or none). A row whose date cannot be read is
    refused alone.

    Raises
    ------
    ConfigError
        The manifest cannot be read, lacks a column, has an unknown column, a
        row without unit or file, or two models for one unit.

    Example
    -------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "m.csv").write_text("unit,file,date\\nEMA-1,a.csv,2026-03-01\\n")
    >>> rec = read_manifest(folder / "m.csv")[0]
    >>> rec.unit, rec.path == folder / "a.csv", rec.test_date.isoformat()
    ('EMA-1', True, '2026-03-01T00:00:00+00:00')
    """
    path = Path(manifest)
    rows = _manifest_rows(path)
    base = path.parent
    models: dict[str, tuple[str | None, int]] = {}
    records = []
    for n, row in rows:
        unit, file = (str(row.get(k) or "").strip() for k in ("unit", "file"))
        if not unit or not file:
            raise ConfigError(f"{path}: row {n}: needs a unit and a file")
        model = str(row.get("model") or "").strip() or None
        if model is not None and model.lower().endswith(".toml") and not Path(model).is_absolute():
            model = str(base / model)
        if unit in models and models[unit][0] != model:
            raise ConfigError(f"{path}: row {n}: unit {unit!r} has model {model or 'none'!r}; "
                              f"row {models[unit][1]} gave {models[unit][0] or 'none'!r} (one "
                              "model per unit)")
        models.setdefault(unit, (model, n))
        file_path = Path(file) if Path(file).is_absolute() else base / file
        when: datetime | None = None
        error = None
        raw_date = row.get("date")
        if raw_date not in (None, ""):
            try:
                when = parse_date(raw_date if isinstance(raw_date, datetime) else str(raw_date),
                                  f"{path}: row {n}: date")
            except DataError as exc:
                error = str(exc)
        records.append(FleetRecord(unit, file_path, model, None, when, error))
    return records


def _manifest_rows(path: Path) -> list[tuple[int, dict[str, Any]]]:
    """``(row number, {column: value})`` of a CSV (numbered as lines) or TOML manifest."""
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".toml"):
        raise ConfigError(f"{path}: unknown manifest type {suffix!r}; allowed: .csv, .toml")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ConfigError(f"{path}: manifest not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the manifest: {_one_line(exc)}") from None
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not TOML: {_one_line(exc)}") from None
        entries = doc.get("records")
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise ConfigError(f"{path}: needs [[records]] tables with unit, file (and "
                              "optionally model, date)")
        rows = list(enumerate(entries, start=1))
    else:
        reader = csv.DictReader(text.splitlines())
        header = [h.strip() for h in reader.fieldnames or []]
        missing = [c for c in ("unit", "file") if c not in header]
        if missing:
            raise ConfigError(f"{path}: missing column {missing[0]!r}; columns: "
                              f"{', '.join(MANIFEST_COLUMNS)} (unit and file required)")
        reader.fieldnames = header
        rows = [(n, row) for n, row in enumerate(reader, start=2)
                if any((v or "").strip() for v in row.values() if isinstance(v, str))]
    for n, row in rows:
        unknown = [k for k in row if k not in MANIFEST_COLUMNS]
        if unknown:
            raise ConfigError(f"{path}: row {n}: unknown column {unknown[0]!r}; allowed: "
                              f"{', '.join(MANIFEST_COLUMNS)}")
    return rows

