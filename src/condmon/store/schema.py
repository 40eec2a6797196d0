"""Tables of the history store and the schema version with its migration path."""

from __future__ import annotations

from collections.abc import Callable
from datetime import datetime
from typing import Any

import sqlalchemy as sa

__all__ = ["metadata", "units", "tests", "estimates", "baselines", "baseline_values",
           "symptoms", "diagnoses", "diagnosis_faults", "isolations", "isolation_estimates",
           "audit", "meta", "forecasts", "unit_states", "declarations", "SCHEMA_VERSION",
           "MIGRATIONS", "NAME_LENGTH", "PARAMETER_LENGTH"]

#: Version of the schema this code writes.
SCHEMA_VERSION = 13

#: Longest unit, fault or baseline name the store keeps (the same on every back-end).
NAME_LENGTH = 200

#: Longest parameter name: a declared name with its regime (``Tc@forward, load=ball``).
PARAMETER_LENGTH = 200

class TolerantDateTime(sa.types.TypeDecorator[datetime]):
    """A date-time column that reads a value it cannot parse (a row written by
    hand or by another tool) as unknown (None) instead of failing the whole
    query: one bad row must not take a history's pages down."""

    impl = sa.DateTime(timezone=True)
    cache_ok = True

    def result_processor(self, dialect: sa.Dialect, coltype: Any) -> Any:
        inner = self.impl_instance.dialect_impl(dialect).result_processor(dialect, coltype)

        def process(value: Any) -> Any:
            if value is None:
                return None
            if isinstance(value, datetime):
                return value
            try:
                return inner(value) if inner is not None else value
            except (ValueError, TypeError, OverflowError):
                return None
        return process


#: Beyond this magnitude a stored number is read as unknown: no quantity condmon
#: stores (SI values, percent changes, seconds) comes near it, while another
#: tool's stand-in for infinity (1e308) or an overflow does, and would break
#: every sum and figure made of it.
MAX_STORED = 1e100


class TolerantFloat(sa.types.TypeDecorator[float]):
    """A number column that reads a value that is not a number, not finite, or
    beyond :data:`MAX_STORED` as unknown (None)."""

    impl = sa.Float
    cache_ok = True

    def process_result_value(self, value: Any, dialect: sa.Dialect) -> float | None:
        if value is None:
            return None
        try:
            number = float(value)
        except (ValueError, TypeError, OverflowError):
            return None
        return number if abs(number) <= MAX_STORED else None  # NaN fails the test too


metadata = sa.MetaData()

meta = sa.Table(
    "condmon_meta", metadata,
    sa.Column("key", sa.String(64), primary_key=True),
    sa.Column("value", sa.Text, nullable=False),
)

units = sa.Table(
    "units", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("name", sa.String(NAME_LENGTH), nullable=False, unique=True),
    sa.Column("model", sa.String(64), nullable=False),
    sa.Column("created_at", TolerantDateTime(), nullable=False),
    sa.Column("model_source", sa.Text, nullable=True),        # declaration file, if not shipped
    sa.Column("baseline_name", sa.String(64), nullable=False, server_default="default"),
    sa.Column("group_name", sa.String(NAME_LENGTH), nullable=True),  # v5: peers it is judged with
    sa.Column("model_digest", sa.String(64), nullable=True),  # v12: its kept declaration
    sa.Column("end_of_life", sa.Text, nullable=True),  # v13: JSON {indicator: "< 0.88"}
)

#: v12: each user's declaration a unit was monitored with, kept whole
#: (condmon.models.bundle), so a history outlives its files.
declarations = sa.Table(
    "declarations", metadata,
    sa.Column("digest", sa.String(64), primary_key=True),
    sa.Column("name", sa.String(64), nullable=False),
    sa.Column("files", sa.Text, nullable=False),
    sa.Column("created_at", TolerantDateTime(), nullable=False),
)

tests = sa.Table(
    "tests", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), nullable=False),
    sa.Column("created_at", TolerantDateTime(), nullable=False),
    sa.Column("source", sa.Text, nullable=False),
    sa.Column("file_hash", sa.String(64), nullable=False),
    sa.Column("role", sa.String(16), nullable=False),          # "baseline" | "check"
    sa.Column("accepted", sa.Boolean, nullable=False),
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("fit_percent", TolerantFloat(), nullable=True),
    sa.Column("fits", sa.Text, nullable=False),                # JSON {output: %}
    sa.Column("method", sa.String(16), nullable=False),
    sa.Column("closed_loop", sa.Boolean, nullable=False),
    sa.Column("constants", sa.Text, nullable=False),           # JSON {name: value} [SI]
    # v11: the record's operating conditions, JSON {name: value} (NULL: none declared)
    sa.Column("conditions", sa.Text, nullable=True),
    # v3: the record's content hash (a re-saved copy is the same test), the
    # test's own date, and exclusion (a test is never deleted)
    sa.Column("record_hash", sa.String(64), nullable=False, server_default=""),
    sa.Column("test_date", TolerantDateTime(), nullable=True),
    sa.Column("excluded", sa.Boolean, nullable=False, server_default=sa.false()),
    sa.Column("excluded_reason", sa.Text, nullable=True),
    # v4: a few figures per column, to recognise a copy rounded otherwise
    sa.Column("fingerprint", sa.Text, nullable=True),
    # v5: the operating regime(s) of the windows estimated ("" or NULL: none declared)
    sa.Column("regime", sa.Text, nullable=True),
    sa.Column("hours", TolerantFloat(), nullable=True),       # v6: operating hours at the test [h]
    sa.Column("cycle", TolerantFloat(), nullable=True),       # v13: the unit's cycle at the test
    sa.UniqueConstraint("unit_id", "file_hash", name="uq_test_file"),
    sa.Index("uq_test_record", "unit_id", "record_hash", unique=True),
    # v9: a record filed under another unit is looked up by its hash at every
    # check (the index above leads with the unit: that look-up read every test)
    sa.Index("ix_tests_record_hash", "record_hash"),
)

estimates = sa.Table(
    "estimates", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("parameter", sa.String(PARAMETER_LENGTH), primary_key=True),
    sa.Column("value", TolerantFloat(), nullable=True),
    sa.Column("std_error", TolerantFloat(), nullable=True),
    # v11: the systematic part from the sensors' stated accuracy (NULL: none stated)
    sa.Column("systematic", TolerantFloat(), nullable=True),
)

baselines = sa.Table(
    "baselines", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), nullable=False),
    sa.Column("created_at", TolerantDateTime(), nullable=False),
    sa.Column("n", sa.Integer, nullable=False),
    sa.Column("test_ids", sa.Text, nullable=False),            # JSON list
    sa.Column("name", sa.String(64), nullable=False, server_default="default"),
    sa.Column("version", sa.Integer, nullable=False, server_default="1"),
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("flags", sa.Text, nullable=False, server_default="[]"),  # JSON [{...}]
)

baseline_values = sa.Table(
    "baseline_values", metadata,
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), primary_key=True),
    sa.Column("parameter", sa.String(PARAMETER_LENGTH), primary_key=True),
    sa.Column("mean", TolerantFloat(), nullable=False),
    sa.Column("std", TolerantFloat(), nullable=False),
    sa.Column("n", sa.Integer, nullable=True),  # v5: tests with this parameter (NULL: all)
)

symptoms = sa.Table(
    "symptoms", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("parameter", sa.String(PARAMETER_LENGTH), primary_key=True),
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), primary_key=True),
    sa.Column("percent_change", TolerantFloat(), nullable=False),
    sa.Column("high", TolerantFloat(), nullable=False),
    sa.Column("low", TolerantFloat(), nullable=False),
)

diagnoses = sa.Table(
    "diagnoses", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), primary_key=True),
    sa.Column("status", sa.String(16), nullable=False),
    sa.Column("condition", TolerantFloat(), nullable=False),
    sa.Column("summary", sa.Text, nullable=False),
)

diagnosis_faults = sa.Table(
    "diagnosis_faults", metadata,
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), primary_key=True),
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), primary_key=True),
    sa.Column("name", sa.String(NAME_LENGTH), primary_key=True),
    sa.Column("degree", TolerantFloat(), nullable=False),
    sa.Column("severity", sa.String(16), nullable=False),
    sa.Column("advice", sa.Text, nullable=False),
)

isolations = sa.Table(
    "isolations", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), nullable=False),
    sa.Column("created_at", TolerantDateTime(), nullable=False),
    sa.Column("test_date", TolerantDateTime(), nullable=True),
    sa.Column("source", sa.Text, nullable=False),
    sa.Column("file_hash", sa.String(64), nullable=False),
    sa.Column("record_hash", sa.String(64), nullable=False),
    sa.Column("model", sa.String(64), nullable=False),
    sa.Column("detected", sa.Boolean, nullable=False),
    sa.Column("detection_time", TolerantFloat(), nullable=True),
    sa.Column("decided", sa.Boolean, nullable=False),
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("statement", sa.Text, nullable=False),
    sa.Column("suspects", sa.Text, nullable=False),             # JSON list
    sa.Column("isolated", sa.Text, nullable=False),             # JSON list
    sa.Column("result", sa.Text, nullable=False),               # JSON: the isolate document
    sa.Column("excluded", sa.Boolean, nullable=False, server_default=sa.false()),
    sa.Column("excluded_reason", sa.Text, nullable=True),
    sa.Column("fingerprint", sa.Text, nullable=True),           # v4, as tests'
    sa.Index("uq_isolation_record", "unit_id", "record_hash", unique=True),
)

isolation_estimates = sa.Table(
    "isolation_estimates", metadata,
    sa.Column("isolation_id", sa.Integer, sa.ForeignKey("isolations.id"), primary_key=True),
    sa.Column("parameter", sa.String(PARAMETER_LENGTH), primary_key=True),
    sa.Column("value", TolerantFloat(), nullable=True),
    sa.Column("nominal", TolerantFloat(), nullable=True),
    sa.Column("change_percent", TolerantFloat(), nullable=True),
    sa.Column("error_sigma", TolerantFloat(), nullable=True),          # model output error [noise sd]
    sa.Column("rejected", sa.Text, nullable=True),              # why left out, if it was
)

#: Each unit's earliest forecast to no-go, kept so a fleet listing does not
#: forecast every unit (v6). Valid while the unit's history is as it was (its
#: latest audit row) and so is the count of degraded units it learns from.
forecasts = sa.Table(
    "forecasts", metadata,
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), primary_key=True),
    sa.Column("audit_id", sa.Integer, nullable=False),
    sa.Column("peers", sa.Integer, nullable=False),
    sa.Column("computed_at", TolerantDateTime(), nullable=False),
    sa.Column("summary", sa.Text, nullable=True),               # JSON, None: no forecast
    sa.Column("reason", sa.Text, nullable=True),                # why there is none
    # for ordering a fleet by urgency in SQL: the median crossing's date (dated
    # forecasts) and the median tests (days, hours) left
    sa.Column("crossing_date", TolerantDateTime(), nullable=True),
    sa.Column("median", TolerantFloat(), nullable=True),
    # v8: a degraded unit's own degradation rates, JSON {"<by>|<parameter>": [rate, se]},
    # what its peers' fleet prior learns from it (valid with the same audit_id)
    sa.Column("rates", sa.Text, nullable=True),
)

#: Each unit's latest status, worked out again by every write that changes the
#: unit (v8; :mod:`condmon.store.states`): a fleet is listed, counted and paged
#: from these rows, whatever the length of its histories.
unit_states = sa.Table(
    "unit_states", metadata,
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), primary_key=True),
    sa.Column("mark", sa.Integer, nullable=False),              # the unit's latest audit row
    sa.Column("status", sa.String(32), nullable=True),          # None: nothing stored yet
    sa.Column("latest_source", sa.Text, nullable=True),
    sa.Column("latest_date", TolerantDateTime(), nullable=True),
    sa.Column("summary", sa.Text, nullable=True),
    sa.Column("latest_regime", sa.Text, nullable=True),
    sa.Column("tests", sa.Integer, nullable=False),
    sa.Column("isolations", sa.Integer, nullable=False),
    sa.Column("degraded", sa.Boolean, nullable=False),          # a check advisory or no-go
    # the unit's newest test, isolation and baseline rows seen: rows another tool adds are found
    sa.Column("last_test", sa.Integer, nullable=True),
    sa.Column("last_isolation", sa.Integer, nullable=True),
    sa.Column("last_baseline", sa.Integer, nullable=True),
    sa.Index("ix_unit_states_status", "status"),
)

#: Every change to a history: who, when, what and why. Nothing is deleted.
audit = sa.Table(
    "audit", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("at", TolerantDateTime(), nullable=False),
    sa.Column("actor", sa.String(NAME_LENGTH), nullable=False),  # user@host
    sa.Column("action", sa.String(32), nullable=False),
    sa.Column("unit_id", sa.Integer, sa.ForeignKey("units.id"), nullable=True),
    sa.Column("test_id", sa.Integer, sa.ForeignKey("tests.id"), nullable=True),
    sa.Column("isolation_id", sa.Integer, sa.ForeignKey("isolations.id"), nullable=True),
    sa.Column("baseline_id", sa.Integer, sa.ForeignKey("baselines.id"), nullable=True),
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("detail", sa.Text, nullable=True),
    sa.Index("ix_audit_unit", "unit_id", "id"),   # v6: a unit's latest change, at once
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


def _rebuild(conn: sa.Connection, table: sa.Table, columns: list[str]) -> None:
    """Re-create ``table`` with its current definition (a new primary key),
    keeping its rows: new table under a temporary name, copy, drop, rename."""
    md = sa.MetaData()
    for t in (units, tests, baselines):
        t.to_metadata(md)
    tmp = table.to_metadata(md, name=f"{table.name}_v3")
    tmp.create(conn)
    cols = ", ".join(columns)
    conn.execute(sa.text(f"INSERT INTO {tmp.name} ({cols}) SELECT {cols} FROM {table.name}"))
    conn.execute(sa.text(f"DROP TABLE {table.name}"))
    conn.execute(sa.text(f"ALTER TABLE {tmp.name} RENAME TO {table.name}"))


def _v2_to_v3(conn: sa.Connection) -> None:
    """Content-addressed tests with their own date and exclusion; named,
    versioned baselines with flags; a check's evaluation kept per baseline."""
    false = "false" if conn.dialect.name == "postgresql" else "0"
    for ddl in (
        "ALTER TABLE units ADD COLUMN baseline_name VARCHAR(64) NOT NULL DEFAULT 'default'",
        "ALTER TABLE tests ADD COLUMN record_hash VARCHAR(64) NOT NULL DEFAULT ''",
        "ALTER TABLE tests ADD COLUMN test_date TIMESTAMP",
        f"ALTER TABLE tests ADD COLUMN excluded BOOLEAN NOT NULL DEFAULT {false}",
        "ALTER TABLE tests ADD COLUMN excluded_reason TEXT",
        # records stored before v3 are known by their file's hash only
        "UPDATE tests SET record_hash = file_hash",
        "CREATE UNIQUE INDEX uq_test_record ON tests (unit_id, record_hash)",
        "ALTER TABLE baselines ADD COLUMN name VARCHAR(64) NOT NULL DEFAULT 'default'",
        "ALTER TABLE baselines ADD COLUMN version INTEGER NOT NULL DEFAULT 1",
        "ALTER TABLE baselines ADD COLUMN reason TEXT",
        "ALTER TABLE baselines ADD COLUMN flags TEXT NOT NULL DEFAULT '[]'",
    ):
        conn.execute(sa.text(ddl))
    rows = conn.execute(sa.text("SELECT id, unit_id FROM baselines ORDER BY id")).all()
    seen: dict[int, int] = {}
    for bid, uid in rows:
        seen[uid] = seen.get(uid, 0) + 1
        conn.execute(sa.text("UPDATE baselines SET version = :v WHERE id = :i"),
                     {"v": seen[uid], "i": bid})
    _rebuild(conn, symptoms, ["test_id", "parameter", "baseline_id", "percent_change",
                              "high", "low"])
    _rebuild(conn, diagnoses, ["test_id", "baseline_id", "status", "condition", "summary"])
    md = sa.MetaData()
    for t in (units, tests, baselines):
        t.to_metadata(md)
    tmp = diagnosis_faults.to_metadata(md, name="diagnosis_faults_v3")
    tmp.create(conn)
    conn.execute(sa.text(
        "INSERT INTO diagnosis_faults_v3 (test_id, baseline_id, name, degree, severity, advice) "
        "SELECT f.test_id, d.baseline_id, f.name, f.degree, f.severity, f.advice "
        "FROM diagnosis_faults f JOIN diagnoses d ON d.test_id = f.test_id"))
    conn.execute(sa.text("DROP TABLE diagnosis_faults"))
    conn.execute(sa.text("ALTER TABLE diagnosis_faults_v3 RENAME TO diagnosis_faults"))


def _v3_to_v4(conn: sa.Connection) -> None:
    """Record fingerprints (tests and isolations stored before have none and are
    known by their hashes only)."""
    inspector = sa.inspect(conn)
    for table in ("tests", "isolations"):  # isolations may be new, made with the column
        if "fingerprint" not in {c["name"] for c in inspector.get_columns(table)}:
            conn.execute(sa.text(f"ALTER TABLE {table} ADD COLUMN fingerprint TEXT"))


def _v4_to_v5(conn: sa.Connection) -> None:
    """Regimes and groups: a test's operating regime, a baseline parameter's own
    count (a regime's parameters are in some tests only), a unit's group, and
    parameter names long enough for a regime (``Tc@forward``)."""
    for ddl in ("ALTER TABLE tests ADD COLUMN regime TEXT",
                "ALTER TABLE baseline_values ADD COLUMN n INTEGER",
                f"ALTER TABLE units ADD COLUMN group_name VARCHAR({NAME_LENGTH})"):
        conn.execute(sa.text(ddl))
    if conn.dialect.name == "postgresql":  # SQLite does not enforce a VARCHAR's length
        for table in ("estimates", "baseline_values", "symptoms", "isolation_estimates"):
            conn.execute(sa.text(f"ALTER TABLE {table} ALTER COLUMN parameter TYPE "
                                 f"VARCHAR({PARAMETER_LENGTH})"))


def _v5_to_v6(conn: sa.Connection) -> None:
    """Kept forecasts: the ``forecasts`` table, new, is made by ``create_all``
    before the migrations run; the audit gets an index by unit (a unit's
    latest change is what a kept forecast is checked against); a test keeps
    the unit's operating hours, when given."""
    conn.execute(sa.text("ALTER TABLE tests ADD COLUMN hours FLOAT"))
    for index in audit.indexes:
        index.create(conn, checkfirst=True)


def _v6_to_v7(conn: sa.Connection) -> None:
    """The columns a history written while v6 was being made may lack: a
    test's operating hours, a kept forecast's crossing date and median (each
    added only where it is missing)."""
    have = {t: {c["name"] for c in sa.inspect(conn).get_columns(t)}
            for t in ("tests", "forecasts")}
    for table, column, kind in (("tests", "hours", "FLOAT"),
                                ("forecasts", "crossing_date", "TIMESTAMP"),
                                ("forecasts", "median", "FLOAT")):
        if column not in have[table]:
            conn.execute(sa.text(f"ALTER TABLE {table} ADD COLUMN {column} {kind}"))


def _v7_to_v8(conn: sa.Connection) -> None:
    """Each unit's latest status kept (``unit_states``): the table, new, is made
    by ``create_all``; the store fills it for every unit once the migrations
    have run (:func:`condmon.store.states.write_states`). A kept forecast
    keeps its unit's degradation rates (``forecasts.rates``)."""
    if "rates" not in {c["name"] for c in sa.inspect(conn).get_columns("forecasts")}:
        conn.execute(sa.text("ALTER TABLE forecasts ADD COLUMN rates TEXT"))


def _v8_to_v9(conn: sa.Connection) -> None:
    """The tests' content hash indexed alone: a check looks up copies of its
    record under other units by it."""
    for index in tests.indexes:
        if index.name == "ix_tests_record_hash":
            index.create(conn, checkfirst=True)


def _v9_to_v10(conn: sa.Connection) -> None:
    """No table changes: a unit with undated checks takes its last stored check
    as its latest (an undated check's storing time is not when it was tested);
    the store works out every unit's status again once the migrations have run."""


def _v10_to_v11(conn: sa.Connection) -> None:
    """Each estimate keeps its systematic part from the sensors' stated
    accuracy (``estimates.systematic``), each test its operating conditions
    (``tests.conditions``); NULL for what was stored before."""
    if "systematic" not in {c["name"] for c in sa.inspect(conn).get_columns("estimates")}:
        conn.execute(sa.text("ALTER TABLE estimates ADD COLUMN systematic FLOAT"))
    if "conditions" not in {c["name"] for c in sa.inspect(conn).get_columns("tests")}:
        conn.execute(sa.text("ALTER TABLE tests ADD COLUMN conditions TEXT"))


def _v11_to_v12(conn: sa.Connection) -> None:
    """Units keep their declaration (the ``declarations`` table, new, made by
    ``create_all``; ``units.model_digest``). A unit whose declaration file is
    still where it was gets it kept now; the others keep none until
    ``condmon unit set-model`` names the file again."""
    from datetime import datetime, timezone

    from condmon.errors import ConfigError
    from condmon.models.bundle import declaration_bundle

    if "model_digest" not in {c["name"] for c in sa.inspect(conn).get_columns("units")}:
        conn.execute(sa.text("ALTER TABLE units ADD COLUMN model_digest VARCHAR(64)"))
    rows = conn.execute(sa.text("SELECT id, model_source FROM units "
                                "WHERE model_source IS NOT NULL")).all()
    for uid, source in rows:
        try:
            bundle = declaration_bundle(str(source))
        except ConfigError:
            continue   # gone or unreadable: `condmon unit set-model` names it again
        if conn.execute(sa.select(declarations.c.digest).where(
                declarations.c.digest == bundle.digest)).first() is None:
            conn.execute(sa.insert(declarations).values(
                digest=bundle.digest, name=bundle.name[:64], files=bundle.to_json(),
                created_at=datetime.now(timezone.utc)))
        conn.execute(sa.text("UPDATE units SET model_digest = :d WHERE id = :i"),
                     {"d": bundle.digest, "i": uid})


def _v12_to_v13(conn: sa.Connection) -> None:
    """A test may stand at a cycle of its unit (``tests.cycle``: an imported
    value per charge cycle), and a unit may have its own end of life
    (``units.end_of_life``); NULL for what was stored before."""
    if "cycle" not in {c["name"] for c in sa.inspect(conn).get_columns("tests")}:
        conn.execute(sa.text("ALTER TABLE tests ADD COLUMN cycle FLOAT"))
    if "end_of_life" not in {c["name"] for c in sa.inspect(conn).get_columns("units")}:
        conn.execute(sa.text("ALTER TABLE units ADD COLUMN end_of_life TEXT"))


MIGRATIONS: dict[int, Callable[[sa.Connection], None]] = {1: _v1_to_v2, 2: _v2_to_v3,
                                                          3: _v3_to_v4, 4: _v4_to_v5,
                                                          5: _v5_to_v6, 6: _v6_to_v7,
                                                          7: _v7_to_v8, 8: _v8_to_v9,
                                                          9: _v9_to_v10, 10: _v10_to_v11,
                                                          11: _v11_to_v12, 12: _v12_to_v13}
