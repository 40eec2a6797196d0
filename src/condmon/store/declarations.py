"""The declarations a history keeps with its units (schema v12).

A unit monitored with a user's declaration keeps its text and that of its
``[monitor]`` files (:mod:`condmon.models.bundle`), keyed by the digest of
what they mean. Where the unit's file is no longer found (moved, renamed,
another machine's path in a shared database), the kept text is written to a
cache folder and read from there, so ``history``, ``report`` and
``forecast`` keep working.
"""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime, timezone
from pathlib import Path

import sqlalchemy as sa

from condmon.errors import ConfigError
from condmon.models.bundle import DeclarationBundle, declaration_bundle, materialise
from condmon.store import schema as S

__all__ = ["keep_declaration", "keep_bundles", "kept_declaration", "resolved_model",
           "bundle_digest"]


def bundle_digest(source: str | Path) -> str | None:
    """The digest of the declaration at ``source`` (None when it cannot be read)."""
    try:
        return declaration_bundle(source).digest
    except ConfigError:
        return None


def keep_declaration(conn: sa.Connection, source: str, *, quiet: bool = False) -> str | None:
    """Keep the declaration at ``source`` (once per digest); its digest.

    ``quiet``: a file that cannot be read keeps nothing and gives None (a
    migration keeps what it can); otherwise the error is raised.
    """
    try:
        bundle = declaration_bundle(source)
    except ConfigError:
        if quiet:
            return None
        raise
    keep_bundles(conn, (bundle,))
    return bundle.digest


def keep_bundles(conn: sa.Connection, bundles: Iterable[DeclarationBundle]) -> None:
    """Keep each bundle the history does not have yet."""
    t = S.declarations
    for bundle in bundles:
        if conn.execute(sa.select(t.c.digest).where(t.c.digest == bundle.digest)
                        ).first() is None:
            conn.execute(sa.insert(t).values(digest=bundle.digest, name=bundle.name[:64],
                                             files=bundle.to_json(),
                                             created_at=datetime.now(timezone.utc)))


def kept_declaration(conn: sa.Connection, digest: str) -> DeclarationBundle | None:
    """The kept bundle of ``digest`` (None when the history has none)."""
    t = S.declarations
    row = conn.execute(sa.select(t.c.name, t.c.files).where(t.c.digest == digest)).first()
    return None if row is None else DeclarationBundle.from_json(digest, str(row[0]), str(row[1]))


def resolved_model(conn: sa.Connection, model: str, source: str | None,
                   digest: str | None) -> str:
    """What :func:`condmon.models.get_model` takes for a unit: its declaration
    file where it still is, else the kept copy (written to the cache folder),
    else the shipped model's name.

    Raises
    ------
    ConfigError
        The file is gone and the history keeps no copy: naming the file and
        ``condmon unit set-model``.
    """
    if not source:
        return model
    if Path(source).is_file():
        return source
    bundle = kept_declaration(conn, digest) if digest else None
    if bundle is None:
        raise ConfigError(f"{source}: declaration file not found, and the history keeps no "
                          f"copy of it (kept since schema v12); name it again with "
                          f"`condmon unit set-model UNIT FILE`")
    return str(materialise(bundle))
