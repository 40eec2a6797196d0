"""Commands that manage a history: exclude, include, baseline rebuild/list, audit."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import err, fmt, id_runs, out, write_json

if TYPE_CHECKING:
    from condmon.store.db import HistoryStore
    from condmon.workflows.manage import ChangeResult

__all__ = ["register", "print_flags"]

DbOpt = Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the result as JSON.")]


def print_flags(flags: Any, unit: str) -> None:
    """Warn (stderr) about a baseline's plausibility flags, with the tests to look
    at or what to do (a trend: the tests to build it from); a note (the tests'
    scatter against their standard errors) is said as a note, no warning."""
    import shlex

    from condmon.monitor.baseline_checks import is_warning

    shown: set[tuple[int, ...]] = set()  # one rebuild command per set of tests kept
    for f in flags:
        if not is_warning(f):
            # "spread": the same ratio, as a warning of an older condmon's baseline
            tail = ("; the scatter, not the standard error, is the yardstick of a check"
                    if f.get("kind") == "spread" else "")
            err.print(f"note: baseline of {unit}: {f['message']}{tail}", highlight=False,
                      markup=False, soft_wrap=True)
        elif f.get("kind") == "trend":
            keep = tuple(int(t) for t in f.get("keep") or [])
            rebuild = (f"; `condmon baseline rebuild --unit {shlex.quote(unit)} --tests "
                       f"{','.join(map(str, keep))} --reason 'warm-up left out'` builds it "
                       "without them" if keep and keep not in shown else "")
            shown.add(keep)
            err.print(f"warning: baseline of {unit}: {f['message']}{rebuild}", highlight=False,
                      markup=False, soft_wrap=True)
        else:
            err.print(f"warning: baseline of {unit}: {f['message']} — look at "
                      f"{', '.join(f'#{t}' for t in f['tests'])}; `condmon exclude TEST "
                      "--reason ...` takes a wrong one out", highlight=False, markup=False,
                      soft_wrap=True)


def _print_change(res: ChangeResult) -> None:
    out.print(f"{res.unit}: {res.message}", highlight=False, markup=False, soft_wrap=True)
    if res.reevaluated:
        moved = res.changed_status
        out.print(f"{len(res.reevaluated)} check(s) evaluated against the new baseline; "
                  f"{len(moved)} changed status"
                  + ("" if not moved else ": " + ", ".join(
                      f"#{k} {b} -> {a}" for k, (b, a) in sorted(moved.items()))),
                  highlight=False, markup=False, soft_wrap=True)
    if res.baseline is not None:
        print_flags(res.baseline.flags, res.unit)


def _change(db: str, as_json: bool, run: Callable[[HistoryStore], ChangeResult]) -> None:
    """Open the (existing) history, make one change, print what it did."""
    from condmon.store.db import open_store

    with open_store(db, create=False) as store:
        res = run(store)
    if as_json:
        write_json(res.to_dict())
        return
    _print_change(res)


def _record_id(text: str) -> tuple[str, int]:
    """``("test", 12)`` for ``12`` or ``#12``, ``("isolation", 3)`` for ``i3``."""
    import re

    m = re.fullmatch(r"\s*(#|[iI])?(\d+)\s*", text)
    if m is None:
        from condmon.errors import ConfigError

        raise ConfigError(f"{text!r} is not a test id (12 or #12) nor an isolation id (i3)")
    return ("isolation" if (m.group(1) or "").lower() == "i" else "test"), int(m.group(2))


def register(app: typer.Typer, baseline_app: typer.Typer) -> None:
    """Add the history-management commands to the CLI."""
    unit_app = typer.Typer(no_args_is_help=True, help="Look after a unit's record in the "
                                                      "history.")
    app.add_typer(unit_app, name="unit")

    @unit_app.command("set-model")
    def set_model_cmd(
        unit: Annotated[str, typer.Argument(help="The unit.")],
        model: Annotated[str, typer.Argument(help="Its declaration file (.toml): moved, renamed, or a new version.")],
        reason: Annotated[Optional[str], typer.Option(help="Why (kept in the audit trail; default: whether the declaration means the same).")] = None,
        db: DbOpt = "condmon.db",
        as_json: JsonOpt = False,
    ) -> None:
        """Point a unit at its declaration file again: the history keeps the file's
        text with the unit, and the audit trail shows the change."""
        from condmon.workflows.manage import set_unit_model

        _change(db, as_json, lambda store: set_unit_model(store, unit, model, reason))

    @app.command("exclude")
    def exclude_cmd(
        test: Annotated[str, typer.Argument(help="Test id (`condmon history` shows them as #N), or an isolation's as iN.")],
        reason: Annotated[str, typer.Option(help="Why (kept in the audit trail).")],
        db: DbOpt = "condmon.db",
        as_json: JsonOpt = False,
    ) -> None:
        """Exclude a wrong test or isolation from baselines, trends and reports (kept,
        marked, audited)."""
        from condmon.workflows.manage import exclude_isolation, exclude_test

        kind, ident = _record_id(test)
        _change(db, as_json, lambda store: (exclude_isolation if kind == "isolation"
                                            else exclude_test)(store, ident, reason))

    @app.command("include")
    def include_cmd(
        test: Annotated[str, typer.Argument(help="Id of an excluded test (N) or isolation (iN).")],
        reason: Annotated[Optional[str], typer.Option(help="Why (kept in the audit trail).")] = None,
        db: DbOpt = "condmon.db",
        as_json: JsonOpt = False,
    ) -> None:
        """Include an excluded test again (back into the baseline it was in), or an
        excluded isolation."""
        from condmon.workflows.manage import include_isolation, include_test

        kind, ident = _record_id(test)
        _change(db, as_json, lambda store: (include_isolation if kind == "isolation"
                                            else include_test)(store, ident, reason))

    @baseline_app.command("rebuild")
    def rebuild_cmd(
        unit: Annotated[str, typer.Option("--unit", help="Unit (machine) name.")],
        reason: Annotated[str, typer.Option(help="Why (kept in the audit trail).")],
        name: Annotated[Optional[str], typer.Option(help="Baseline name (default: the unit's active one, 'default' at first); it becomes the active one.")] = None,
        tests: Annotated[Optional[str], typer.Option(help="Test ids to build it from, e.g. 3,4,5 (default: every accepted, not excluded healthy test).")] = None,
        db: DbOpt = "condmon.db",
        as_json: JsonOpt = False,
    ) -> None:
        """A new baseline version from chosen tests; checks are evaluated against it."""
        from condmon.errors import ConfigError
        from condmon.workflows.manage import rebuild_baseline

        ids = None
        if tests is not None:
            try:
                ids = [int(t.strip().lstrip("#")) for t in tests.split(",") if t.strip()]
            except ValueError:
                raise ConfigError(f"--tests: {tests!r} is not a list of test ids "
                                  "(e.g. 3,4,5)") from None
        _change(db, as_json, lambda store: rebuild_baseline(store, unit, reason=reason,
                                                             name=name, test_ids=ids))

    @baseline_app.command("list")
    def list_cmd(
        unit: Annotated[str, typer.Option("--unit", help="Unit (machine) name.")],
        db: DbOpt = "condmon.db",
        as_json: JsonOpt = False,
    ) -> None:
        """Every version of the unit's baselines: tests, reason, flags (* = active)."""
        from condmon.models.regimes import split_key
        from condmon.monitor.baseline_checks import is_warning
        from condmon.models.registry import get_model
        from condmon.store.db import open_store

        with open_store(db, create=False) as store:
            versions = store.baselines(unit)
            active = store.active_baseline_name(unit)
            model = store.unit_model(unit)
        latest = {b.name: b.id for b in versions}
        if as_json:
            write_json({"unit": unit, "active": active,
                        "baselines": [b.to_dict() for b in versions]})
            return
        table = Table(title=escape(f"Baselines of {unit} (* = in use)"), box=box.SIMPLE_HEAD)
        for col in ("", "name", "v", "created", "N", "tests", "flags", "reason"):
            table.add_column(col, overflow="fold")
        for b in versions:
            mark = "*" if b.name == active and latest[b.name] == b.id else ""
            table.add_row(mark, escape(b.name), str(b.version), f"{b.created_at:%Y-%m-%d %H:%M}",
                          str(b.baseline.n), id_runs(b.test_ids),
                          str(sum(map(is_warning, b.flags))) if any(map(is_warning, b.flags))
                          else "", escape(b.reason or ""))
        out.print(table)
        current = [b for b in versions if b.name == active and latest[b.name] == b.id]
        if current:
            b = current[0]
            units = get_model(model).monitored_units if model is not None else {}
            out.print(f"{b.name} v{b.version}: mean ± standard deviation of its tests",
                      highlight=False, markup=False)
            for p, m, sd in zip(b.baseline.parameters, b.baseline.mean, b.baseline.std):
                unit_of = units.get(split_key(p)[0], "")
                out.print(f"  {p}: {fmt(m)} ± {fmt(sd)} {unit_of}".rstrip(), highlight=False,
                          markup=False)
            print_flags(b.flags, unit)

    @app.command("audit")
    def audit_cmd(
        unit: Annotated[Optional[str], typer.Option("--unit", help="Only this unit.")] = None,
        db: DbOpt = "condmon.db",
        as_json: JsonOpt = False,
    ) -> None:
        """Every change to the history: when, who, what, why."""
        from condmon.store.db import open_store
        from condmon.store.engine import redact

        with open_store(db, create=False) as store:
            trail = store.audit(unit)
        if as_json:
            from condmon.io.jsonable import frame_records

            write_json({"audit": frame_records(trail)})
            return
        table = Table(title=escape(f"Audit trail of {unit or redact(db)}"), box=box.SIMPLE_HEAD)
        for col in ("at (UTC)", "who", "action", "unit", "test", "reason"):
            table.add_column(col, overflow="fold", no_wrap=col in ("at (UTC)", "action", "test"))
        import pandas as pd

        for _, r in trail.iterrows():
            def text(key: str) -> str:
                return "" if bool(pd.isna(r[key])) else escape(str(r[key]))

            tid, iid = r["test_id"], r.get("isolation_id")
            ref = ("" if bool(pd.isna(tid)) else f"#{int(tid)}") if iid is None or bool(
                pd.isna(iid)) else f"i{int(iid)}"
            table.add_row(str(r["at"])[:16], text("actor"), text("action"), text("unit"),
                          ref, text("reason"))
        out.print(table)

