"""A declaration as a history keeps it: its text and the files it names.

A unit monitored with a user's declaration is judged by that file and by the
rules and breakpoints files its ``[monitor]`` table names. The history keeps
their text with the unit (:func:`declaration_bundle`), so the unit's history,
reports and forecasts work when the files are moved, renamed or kept at
another path on another machine sharing the database; :func:`materialise`
writes the kept text back to a cache folder to read it from.

The bundle's digest is that of what the files *mean*, not their bytes: the
parsed declaration without its ``[monitor]`` file names, and the parsed rules
and breakpoints. A copy with other comments, other spacing or other file
names is the same declaration; one with another equation, parameter, rule or
breakpoint is not.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from condmon.errors import ConfigError
from condmon.io.config import load_toml

__all__ = ["DeclarationBundle", "declaration_bundle", "materialise", "cache_folder"]

_MONITOR_FILES = ("rules", "breakpoints")


@dataclass(frozen=True)
class DeclarationBundle:
    """A declaration's text and the files it names, with the digest of their meaning.

    Attributes
    ----------
    digest : str
        SHA-256 (hex) of the parsed declaration (without its ``[monitor]``
        file names) and of each parsed monitor file.
    name : str
        The declared ``name``.
    main : str
        The declaration's path relative to the bundle's root (``decl.toml``,
        or ``_/decl.toml`` when a monitor file lies in a parent folder).
    files : dict of str to str
        Each file's text by its path relative to the bundle's root.
    """

    digest: str
    name: str
    main: str
    files: dict[str, str]

    def to_json(self) -> str:
        """The files as one JSON text (what the history keeps)."""
        return json.dumps({"main": self.main, "files": self.files}, sort_keys=True)

    @classmethod
    def from_json(cls, digest: str, name: str, text: str) -> DeclarationBundle:
        """A bundle from the history's JSON text."""
        doc = json.loads(text)
        return cls(digest, name, str(doc["main"]), {str(k): str(v)
                                                     for k, v in doc["files"].items()})


def _read(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the {what}: {err}") from None


def declaration_bundle(path: str | Path) -> DeclarationBundle:
    """The bundle of the declaration at ``path`` and of its ``[monitor]`` files.

    Raises
    ------
    ConfigError
        A file cannot be read or parsed, or a monitor file is named by an
        absolute path (it could not be kept beside its declaration).

    Example
    -------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "m.toml").write_text('name = "m"  # a comment\\n[parameters]\\n')
    >>> _ = (d / "n.toml").write_text('name="m"\\n\\n[parameters]\\n')
    >>> a, b = declaration_bundle(d / "m.toml"), declaration_bundle(d / "n.toml")
    >>> a.digest == b.digest, a.name, a.main
    (True, 'm', 'm.toml')
    """
    main = Path(path)
    doc = load_toml(main)
    monitor = doc.get("monitor", {})
    monitor = monitor if isinstance(monitor, Mapping) else {}
    named = {k: monitor[k] for k in _MONITOR_FILES if isinstance(monitor.get(k), str)}
    meaning: dict[str, Any] = {"declaration": {k: v for k, v in doc.items() if k != "monitor"}}
    rel: dict[str, str] = {}
    for key, ref in named.items():
        if PurePosixPath(ref).is_absolute() or Path(ref).is_absolute():
            raise ConfigError(f"{main}[monitor].{key}: {ref!r} is an absolute path; name it "
                              "relative to the declaration so that it can be kept with it")
        meaning[key] = load_toml(main.parent / ref)
        rel[key] = PurePosixPath(Path(ref).as_posix()).as_posix()
    digest = hashlib.sha256(json.dumps(meaning, sort_keys=True, default=str)
                            .encode("utf-8")).hexdigest()
    # a monitor file in a parent folder ("../rules.toml"): the declaration sits
    # as many folders deep in the bundle as the deepest reference climbs
    depth = max((sum(1 for part in PurePosixPath(r).parts if part == "..")
                 for r in rel.values()), default=0)
    prefix = PurePosixPath(*(["_"] * depth)) if depth else PurePosixPath()
    main_rel = (prefix / main.name).as_posix()
    files = {main_rel: _read(main, "declaration")}
    for key, r in rel.items():
        target = os.path.normpath((prefix / r).as_posix()).replace(os.sep, "/")
        files[target] = _read(main.parent / named[key], f"[monitor].{key} file")
    return DeclarationBundle(digest, str(doc.get("name", main.stem)), main_rel, files)


def cache_folder() -> Path:
    """Where kept declarations are written back to be read: ``$CONDMON_CACHE``,
    else ``$XDG_CACHE_HOME/condmon``, else ``~/.cache/condmon``."""
    if os.environ.get("CONDMON_CACHE"):
        return Path(os.environ["CONDMON_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "condmon"


def materialise(bundle: DeclarationBundle) -> Path:
    """Write a kept bundle to the cache (once) and return its declaration's path.

    Each file is written whole under a temporary name and renamed, so two
    processes materialising the same bundle never read a half-written file.

    Raises
    ------
    ConfigError
        The cache folder cannot be written (naming it and ``CONDMON_CACHE``).
    """
    root = cache_folder() / "declarations" / bundle.digest[:32]
    try:
        for rel, text in bundle.files.items():
            target = root / rel
            if target.is_file() and target.read_text(encoding="utf-8") == text:
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=target.parent, suffix=".part")
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, target)
    except OSError as err:
        raise ConfigError(f"{root}: cannot write the kept declaration {bundle.name!r} there "
                          f"({err.strerror}); set CONDMON_CACHE to a writable folder") from None
    return root / bundle.main
