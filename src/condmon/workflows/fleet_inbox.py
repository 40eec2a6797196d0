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
import os
import re
import tomllib
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from condmon.errors import ConfigError, DataError
from condmon.io.dates import parse_date
from condmon.io.raw import one_line
from condmon.io.readers import READABLE_SUFFIXES
from condmon.io.rig import RECORD_KEYS, RecordSettings, parse_assignments, parse_record_settings

__all__ = ["FleetRecord", "inbox_records", "read_manifest", "UnitFile", "read_unit_file"]

#: Name of a unit folder's optional declaration (``model = "..."``).
UNIT_FILE = "unit.toml"
#: ``NAME.done`` beside ``NAME`` says a dropped file is whole (``watch --complete
#: marker``); it is no record itself.
MARKER = ".done"
#: Names a logger writes a file under before renaming it into place: no records yet.
TEMPORARY = (".part", ".tmp", ".partial")
#: A ``unit.toml`` holds a few keys: past this it is refused unread. [bytes]
MAX_UNIT_FILE = 1_000_000


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
        Why the record is refused before it is read (a manifest row's bad date
        or model, a file that is no record).
    fallback_source : str or None
        The ``unit.toml`` that gave ``fallback_model``.
    skip : str or None
        Why the record is skipped before it is read (a file listed again in
        the manifest).
    settings : RecordSettings or None
        How the rig writes it: ``unit.toml``'s ``[record]`` table, then the
        manifest row's.
    metadata : dict or None
        Its metadata fields (``unit.toml``'s ``[metadata]``, then the row's).
    group : str or None
        The group of peer units it is judged with (``unit.toml``'s or the row's).
    """

    unit: str
    path: Path
    model: str | None = None
    fallback_model: str | None = None
    test_date: datetime | None = None
    error: str | None = None
    fallback_source: str | None = None
    skip: str | None = None
    settings: RecordSettings | None = None
    metadata: dict[str, Any] | None = None
    group: str | None = None


def _natural(text: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key of a name with its numbers compared as numbers (rec-2 < rec-10)."""
    return tuple((0, int(part)) if part.isdigit() else (1, part)
                 for part in re.split(r"(\d+)", text) if part)


def _name_key(path: Path) -> tuple[Any, ...]:
    """File-name order: numbers as numbers, a name before its longer variants
    (``rec-2.csv`` < ``rec-2-copy.csv`` < ``rec-10.csv``)."""
    return (_natural(str(path.with_suffix(""))), path.suffix)


def _readable_suffix(path: Path) -> bool:
    """Whether a reader takes files named like ``path`` (its suffix)."""
    return path.suffix.lower() in READABLE_SUFFIXES


def _is_record(path: Path) -> bool:
    return path.is_file() and not path.name.startswith(".") and _readable_suffix(path)


#: Suffixes of compressed files, named with the suffix before them (``.csv.gz``).
_COMPRESSED = (".gz", ".bz2", ".xz", ".zst", ".zip", ".7z")


def _not_a_record(path: Path) -> str:
    """Why a file in a unit's folder is not read, naming it."""
    suffix = path.suffix
    if suffix.lower() in _COMPRESSED and Path(path.stem).suffix:
        suffix = Path(path.stem).suffix + suffix
    return (f"{path}: not a record file ({suffix or 'no suffix'}); readable: "
            f"{', '.join(READABLE_SUFFIXES)}")


#: Keys a unit folder's ``unit.toml`` may hold.
UNIT_KEYS = ("model", "group", "record", "metadata")


@dataclass(frozen=True)
class UnitFile:
    """What a unit folder's ``unit.toml`` says (all None without one).

    Attributes
    ----------
    model : str or None
        The unit's model (a name or a declaration, resolved against the folder).
    group : str or None
        Its group of peer units.
    settings : RecordSettings or None
        Its ``[record]`` table.
    metadata : dict or None
        Its ``[metadata]`` table (fields its regimes may name, ``load = "ball"``).
    error : str or None
        Why the file cannot be used (its records are refused with it).
    """

    model: str | None = None
    group: str | None = None
    settings: RecordSettings | None = None
    metadata: dict[str, Any] | None = None
    error: str | None = None


def _metadata(value: Any, where: str) -> dict[str, Any]:
    """A ``[metadata]`` table or ``"k=v,..."`` text: text values kept, numbers as numbers."""
    if isinstance(value, str):
        out: dict[str, Any] = {}
        for k, v in parse_assignments(value, where).items():
            try:
                out[k] = float(v)
            except ValueError:
                out[k] = v
        return out
    if not isinstance(value, dict) or not all(
            isinstance(v, (str, int, float)) and not isinstance(v, bool) for v in value.values()):
        raise ConfigError(f"{where} must be a table of text or numbers (load = \"ball\")")
    return dict(value)


def read_unit_file(folder: Path) -> UnitFile:
    """``folder/unit.toml`` read and validated (an empty :class:`UnitFile` without one)."""
    path = folder / UNIT_FILE
    if not path.is_file():
        return UnitFile()
    try:
        size = path.stat().st_size
        if size > MAX_UNIT_FILE:
            return UnitFile(error=f"{path}: {size} bytes, beyond the {MAX_UNIT_FILE} a unit "
                                  "file may hold (it names a model, a group, [record] and "
                                  "[metadata])")
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        return UnitFile(error=f"{path}: cannot read: {one_line(exc, None)}")
    unknown = [k for k in doc if k not in UNIT_KEYS]
    if unknown:
        return UnitFile(error=f"{path}: unknown key {unknown[0]!r}; allowed: "
                              f"{', '.join(UNIT_KEYS)}")
    model = doc.get("model")
    if model is not None and (not isinstance(model, str) or not model.strip()):
        return UnitFile(error=f"{path}: needs model = \"NAME or declaration.toml\"")
    group = doc.get("group")
    if group is not None and (not isinstance(group, str) or not group.strip()):
        return UnitFile(error=f"{path}: group must be a name")
    try:
        settings = parse_record_settings(doc.get("record"), f"{path}[record]")
        metadata = _metadata(doc.get("metadata", {}), f"{path}[metadata]")
    except ConfigError as exc:
        return UnitFile(error=str(exc))
    if model is not None:
        model = model.strip()
        if model.lower().endswith(".toml") and not Path(model).is_absolute():
            model = str(folder / model)
    return UnitFile(model, group.strip() if group else None,
                    None if settings.empty else settings, metadata or None)


def _unit_records(folder: Path) -> list[FleetRecord]:
    """Every file of a unit's folder (sub-folders too) but hidden ones, its
    ``unit.toml`` and the declaration that names; in file-name order."""
    unit_file = read_unit_file(folder)
    model, error = unit_file.model, unit_file.error
    source = str(folder / UNIT_FILE) if (folder / UNIT_FILE).is_file() else None
    declaration = Path(model).resolve() if model and model.lower().endswith(".toml") else None
    files = sorted((p for p in folder.rglob("*")
                    if (p.is_file() or _broken_link(p)) and p.name != UNIT_FILE
                    and not p.name.endswith((MARKER, *TEMPORARY))
                    and not any(part.startswith(".") for part in p.relative_to(folder).parts)
                    and (declaration is None or p.resolve() != declaration)),
                   key=lambda p: _name_key(p.relative_to(folder)))
    return [FleetRecord(folder.name, p, fallback_model=model, fallback_source=source,
                        error=(f"{p}: a link to {os.readlink(p)}, which does not exist"
                               if _broken_link(p) else
                               error if _is_record(p) else _not_a_record(p)),
                        settings=unit_file.settings, metadata=unit_file.metadata,
                        group=unit_file.group) for p in files]


def _broken_link(path: Path) -> bool:
    """A symbolic link whose target does not exist (a record file gone missing)."""
    return path.is_symlink() and not path.exists()


def check_inbox(inbox: str | Path) -> Path:
    """``inbox`` as a Path once it is a folder of unit folders, not a unit's
    own folder (record files and no folders, or a ``unit.toml``): watched or
    run, a unit's folder would have its records never looked at.

    Raises
    ------
    ConfigError
        Not a folder, or a unit's folder ("did you mean" its parent).
    """
    root = Path(inbox)
    if not root.is_dir():
        raise ConfigError(f"{root}: not a folder; the inbox holds a folder per unit "
                          "(INBOX/UNIT/record files)")
    entries = [e for e in root.iterdir() if not e.name.startswith(".")]
    stray = [e for e in entries if _is_record(e)]
    if stray and ((root / UNIT_FILE).is_file() or not any(e.is_dir() for e in entries)):
        parent = root.parent if root.parent.name else root.absolute().parent
        raise ConfigError(f"{root} holds record files, not unit folders — did you mean "
                          f"{parent}?")
    return root


def inbox_records(inbox: str | Path) -> list[FleetRecord]:
    """The records of an inbox folder: ``INBOX/UNIT/...`` (a folder per unit).

    Every file under a unit's folder (sub-folders too) is a record of that
    unit: one with a record suffix (:data:`condmon.io.readers.READABLE_SUFFIXES`)
    is read, any other is refused as not a record file; hidden files and
    folders are ignored. ``INBOX/UNIT/unit.toml`` may name the unit's model
    (``model = "dc-motor-coulomb"`` or a declaration file, relative to the
    folder, which is then no record either), used while the unit has no
    history. A record file directly in the inbox (in no unit's folder) is
    refused; other files there are ignored.

    Raises
    ------
    ConfigError
        ``inbox`` is not a folder, or is a unit's folder (it holds record
        files and no folders, or a ``unit.toml``).

    Example
    -------
    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> for name in ("EMA-1/rec-10.csv", "EMA-1/rec-2.csv", "EMA-1/notes.md"):
    ...     (root / name).parent.mkdir(exist_ok=True)
    ...     _ = (root / name).write_text("t\\n")
    >>> [(r.path.name, r.error is None) for r in inbox_records(root)]
    [('notes.md', False), ('rec-2.csv', True), ('rec-10.csv', True)]
    """
    root = check_inbox(inbox)
    entries = [e for e in sorted(root.iterdir(), key=lambda p: _natural(p.name))
               if not e.name.startswith(".")]
    records: list[FleetRecord] = []
    for entry in entries:
        if entry.is_dir():
            records += _unit_records(entry)
        elif _is_record(entry):
            records.append(FleetRecord("", entry, error=f"{entry}: not in a unit's folder "
                                       "(INBOX/UNIT/record files)"))
    return records


MANIFEST_COLUMNS = ("unit", "file", "model", "date", "group", "metadata", *RECORD_KEYS)
#: Columns of a manifest row that say how its rig writes the record (``[record]``).
_RECORD_COLUMNS = RECORD_KEYS


def read_manifest(manifest: str | Path) -> list[FleetRecord]:
    """The records listed in a manifest (CSV or TOML).

    A CSV manifest has a header with the columns ``unit`` and ``file``, and
    optionally ``model``, ``date``, ``group``, ``metadata`` (``load=ball``) and
    the record settings ``columns`` (``t=Time,theta=Angle``),
    ``sample_rate``, ``scale``, ``offset`` and ``ignore`` (in any case; comma,
    semicolon or tab delimited, told from the header; a value holding the
    delimiter is quoted); a TOML manifest lists ``[[records]]`` tables with
    the same keys (``columns``, ``scale``, ``offset`` and ``metadata`` may be
    tables). A relative ``file`` (and a relative model declaration ``.toml``)
    is resolved against the manifest's folder.

    A row without a model takes its unit's from the unit's other rows (else
    the history's, else the default). A row that cannot be taken is refused
    alone, with its reason: a date that cannot be read, another model than an
    earlier row of its unit gives, an unknown key of a TOML table. A file
    listed again is skipped (``listed twice in the manifest (rows 2 and 3)``).

    Raises
    ------
    ConfigError
        The manifest cannot be read, lacks a column or has an unknown one, or
        has rows without a unit or a file (every such row named, in one line).

    Example
    -------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "m.csv").write_text("Unit;File;Date\\nEMA-1;a.csv;2026-03-01\\n")
    >>> rec = read_manifest(folder / "m.csv")[0]
    >>> rec.unit, rec.path == folder / "a.csv", rec.test_date.isoformat()
    ('EMA-1', True, '2026-03-01T00:00:00+00:00')
    """
    path = Path(manifest)
    base = path.parent
    problems: list[str] = []
    rows: list[tuple[int, str, Path, str | None, dict[str, Any]]] = []
    for n, row in _manifest_rows(path):
        unit, file = (str(row.get(k) or "").strip() for k in ("unit", "file"))
        if not unit or not file:
            problems.append(f"row {n}: needs a unit and a file")
            continue
        model = str(row.get("model") or "").strip() or None
        if model is not None and model.lower().endswith(".toml") and not Path(model).is_absolute():
            model = str(base / model)
        rows.append((n, unit, Path(file) if Path(file).is_absolute() else base / file, model,
                     row))
    if problems:
        raise ConfigError(f"{path}: {'; '.join(problems)}")
    models: dict[str, tuple[str, int]] = {}  # unit -> (model, first row giving it)
    for n, unit, _, model, _ in rows:
        if model is not None:
            models.setdefault(unit, (model, n))
    listed: dict[Path, int] = {}
    records = []
    for n, unit, file_path, model, row in rows:
        error = skip = None
        unknown = [str(k) for k in row if k not in MANIFEST_COLUMNS]
        given = models.get(unit)
        if unknown:
            error = (f"{path}: row {n}: unknown column {unknown[0]!r} (columns: "
                     f"{', '.join(MANIFEST_COLUMNS)})")
        elif model is not None and given is not None and model != given[0]:
            error = (f"{path}: unit {unit!r} has one model: row {n} gives {model!r}, row "
                     f"{given[1]} gave {given[0]!r}")
        when: datetime | None = None
        raw_date = row.get("date")
        if error is None and raw_date not in (None, ""):
            try:
                when = parse_date(raw_date if isinstance(raw_date, datetime) else str(raw_date),
                                  f"{path}: row {n}: date")
            except DataError as exc:
                error = str(exc)
        settings: RecordSettings | None = None
        metadata: dict[str, Any] | None = None
        if error is None:
            try:
                table = {k: row[k] for k in _RECORD_COLUMNS if row.get(k) not in (None, "")}
                parsed = parse_record_settings(table, f"{path}: row {n}")
                settings = None if parsed.empty else parsed
                if row.get("metadata") not in (None, ""):
                    metadata = _metadata(row["metadata"], f"{path}: row {n}: metadata")
            except ConfigError as exc:
                error = str(exc)
        group = str(row.get("group") or "").strip() or None
        key = Path(os.path.normpath(file_path.absolute()))
        if error is None and key in listed:
            skip = f"listed twice in the manifest (rows {listed[key]} and {n})"
        elif error is None:
            listed[key] = n
        records.append(FleetRecord(unit, file_path, given[0] if given else None, None, when,
                                   error, skip=skip, settings=settings, metadata=metadata,
                                   group=group))
    return records


def _manifest_rows(path: Path) -> list[tuple[int, dict[Any, Any]]]:
    """``(row number, {column: value})`` of a CSV (numbered as lines) or TOML
    manifest, its columns in lower case."""
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".toml"):
        raise ConfigError(f"{path}: unknown manifest type {suffix!r}; allowed: .csv, .toml")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ConfigError(f"{path.absolute()}: manifest not found (relative files are found "
                          "from the manifest's folder)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the manifest: {one_line(exc, None)}") from None
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not TOML: {one_line(exc, None)}") from None
        entries = doc.get("records")
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise ConfigError(f"{path}: needs [[records]] tables with unit, file (and "
                              "optionally model, date)")
        return [(n, {str(k).strip().lower(): v for k, v in e.items()})
                for n, e in enumerate(entries, start=1)]
    lines = text.splitlines()
    first = next((line for line in lines if line.strip()), "")
    sep = max(_DELIMITERS, key=lambda d: len(next(csv.reader([first], delimiter=d), [])))
    reader = csv.DictReader(lines, delimiter=sep)
    found = [h.strip() for h in reader.fieldnames or []]
    unknown = [h for h in found if h and h.lower() not in MANIFEST_COLUMNS]
    if unknown:
        raise ConfigError(f"{path}: unknown column {unknown[0]!r} (columns: "
                          f"{', '.join(MANIFEST_COLUMNS)})")
    reader.fieldnames = [h.lower() for h in found]
    missing = [c for c in ("unit", "file") if c not in reader.fieldnames]
    if missing:
        raise ConfigError(f"{path}: missing column {missing[0]!r}; columns: "
                          f"{', '.join(MANIFEST_COLUMNS)} (unit and file required)")
    rows = []
    for row in reader:
        extra = row.pop(None, None)
        values = {k: v for k, v in row.items() if k}
        if extra and any(str(v).strip() for v in extra):
            values["(a value past the last column)"] = extra
        if any((v or "").strip() for v in values.values() if isinstance(v, str)) or extra:
            rows.append((reader.line_num, values))
    return rows


#: Delimiters of a CSV manifest, told from its header (the one giving most columns).
_DELIMITERS = (",", ";", "\t")
