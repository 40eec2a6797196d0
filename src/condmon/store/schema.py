"""Tables of the history store and the schema version with its migration path."""

from __future__ import annotations

from collections.abc import Callable

import sqlalchemy as sa

__all__ = ["metadata", "units", "tests", "estimates", "baselines", "baseline_values",
           "symptoms", "diagnoses", "diagnosis_faults", "meta", "SCHEMA_VERSION",
           "MIGRATIONS"]

#: Version of the schema this code writes.
SCHEMA_VERSION = 2

metadata = sa.MetaData()

meta = sa.Table(
    "condmon_meta", metadata,
    sa.Column("key", sa.String(64), primary_key=True),
    sa.Column("value", sa.Text, nullable=False),
)

units = sa.Table(
    "units", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("name", sa.String(200), nullable=False, unique=True),
    sa.Column("model", sa.String(64), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("model_source", sa.Text, nullable=True),        # declaration file, if not shipped
)

tests = sa.Table(
    "tests", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("source", sa.Text, nullable=False),
    sa.Column("file_hash", sa.String(64), nullable=False),
    sa.Column("role", sa.String(16), nullable=False),          # "baseline" | "check"
    sa.Column("accepted", sa.Boolean, nullable=False),
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("fit_percent", sa.Float, nullable=True),
    sa.Column("fits", sa.Text, nullable=False),                # JSON {output: %}
    sa.Column("method", sa.String(16), nullable=False),
    sa.Column("closed_loop", sa.Boolean, nullable=False),
    sa.Column("constants", sa.Text, nullable=False),           # JSON {name: value} [SI]
    sa.UniqueConstraint("unit_id", "file_hash", name="uq_test_file"),
)

estimates = sa.Table(
    "estimates", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("parameter", sa.String(32), primary_key=True),
    sa.Column("value", sa.Float, nullable=True),
    sa.Column("std_error", sa.Float, nullable=True),
)

baselines = sa.Table(
    "baselines", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("n", sa.Integer, nullable=False),
    sa.Column("test_ids", sa.Text, nullable=False),            # JSON list
)

baseline_values = sa.Table(
    "baseline_values", metadata,
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), primary_key=True),
    sa.Column("parameter", sa.String(32), primary_key=True),
    sa.Column("mean", sa.Float, nullable=False),
    sa.Column("std", sa.Float, nullable=False),
)

symptoms = sa.Table(
    "symptoms", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("parameter", sa.String(32), primary_key=True),
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), nullable=False),
    sa.Column("percent_change", sa.Float, nullable=False),
    sa.Column("high", sa.Float, nullable=False),
    sa.Column("low", sa.Float, nullable=False),
)

diagnoses = sa.Table(
    "diagnoses", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), nullable=False),
    sa.Column("status", sa.String(16), nullable=False),
    sa.Column("condition", sa.Float, nullable=False),
    sa.Column("summary", sa.Text, nullable=False),
)

diagnosis_faults = sa.Table(
    "diagnosis_faults", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("name", sa.String(200), primary_key=True),
    sa.Column("degree", sa.Float, nullable=False),
    sa.Column("severity", sa.String(16), nullable=False),
    sa.Column("advice", sa.Text, nullable=False),
)

#: Upgrades, keyed by the version they start from: MIGRATIONS[v](conn) brings a
#: database from v to v + 1 inside one transaction. Add an entry (and bump
#: SCHEMA_VERSION) whenever a table changes.
def _v1_to_v2(conn: sa.Connection) -> None:
    """Model constants kept generically: ``tests.gamma`` becomes ``tests.constants``
    (JSON ``{"gamma": value}``); units remember a user's declaration file."""
    import json

    conn.execute(sa.text("ALTER TABLE units ADD COLUMN model_source TEXT"))
    conn.execute(sa.text("ALTER TABLE tests ADD COLUMN constants TEXT NOT NULL DEFAULT '{}'"))
    rows = conn.execute(sa.text("SELECT id, gamma FROM tests")).all()
    for tid, gamma in rows:
        doc = json.dumps({} if gamma is None else {"gamma": float(gamma)})
        conn.execute(sa.text("UPDATE tests SET constants = :c WHERE id = :i"),
                     {"c": doc, "i": tid})
    conn.execute(sa.text("ALTER TABLE tests DROP COLUMN gamma"))


MIGRATIONS: dict[int, Callable[[sa.Connection], None]] = {1: _v1_to_v2}
