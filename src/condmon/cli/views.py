"""Reading a history: ``units``, ``history`` and ``report``."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import (
    err, fitted_widths, id_runs, out, progress, status_text, write_json, write_json_list,
)
from condmon.cli.history import print_flags

__all__ = ["register"]

DbOpt = Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")]
UnitOpt = Annotated[str, typer.Option("--unit", help="Unit (machine) name.")]


def register(app: typer.Typer) -> None:
    """Add ``units``, ``history`` and ``report`` to the ``condmon`` application."""

    @app.command("units")
    def units_cmd(
        db: DbOpt = "condmon.db",
        as_json: Annotated[bool, typer.Option("--json", help="Print the units as JSON records, each with its earliest forecast to no-go.")] = False,
        sort: Annotated[str, typer.Option("--sort", help="Order: name; status (the most severe first); date (the latest test first); forecast (the unit forecast to turn no-go soonest first).")] = "name",
        page: Annotated[int, typer.Option("--page", help="Which page of --per-page units (from 1).")] = 1,
        per_page: Annotated[Optional[int], typer.Option("--per-page", help="Units a page (default: all on one).")] = None,
    ) -> None:
        """List the units of a history: model, tests, latest status and when it turns no-go.

        "no-go in": the earliest forecast to no-go of the unit's parameters
        (`condmon forecast --unit U`), the tests (days, hours) left as a median
        and a 90 % interval; "no trend" when none trends towards no-go, "—"
        without enough checks since the baseline."""
        from condmon.errors import ConfigError
        from condmon.monitor.generic import load_generic_settings
        from condmon.store.db import open_store
        from condmon.store.engine import redact
        from condmon.forecast.unit import NO_TREND, remaining_text
        from condmon.report.web_data import fleet_document

        from condmon.report.web_data import SORTS

        if sort not in SORTS:
            raise ConfigError(f"--sort {sort!r}: allowed: {', '.join(SORTS)}")
        least = load_generic_settings().group_min_units
        with open_store(db, create=False) as store:
            if as_json and per_page is None and page == 1 and sort != "forecast":
                _stream_units(store, sort)   # the whole fleet, a chunk at a time
                return
            doc = fleet_document(store, sort=sort, page=page, per_page=per_page)
            small = {g: len(store.group_baselines(g)) for g in store.groups()}
        small = {g: n for g, n in small.items() if n < least}
        rows = doc["units"]
        if as_json:
            write_json(doc)
            return
        if not doc["total"]:
            out.print(f"no units in {redact(db)} yet: `condmon baseline add RECORDS --unit U` "
                      "starts one", markup=False, highlight=False, soft_wrap=True)
            return
        grouped = any(r["group"] for r in rows)
        regimes = any(r["latest_regime"] for r in rows)
        table = Table(title=escape(f"Units in {redact(db)}"), box=box.SIMPLE_HEAD,
                      pad_edge=False, collapse_padding=True)
        # the column when any unit has a forecast, or "no trend" (a stable fleet says so)
        ahead = sort == "forecast" or any(r["forecast"] or r["forecast_reason"] == NO_TREND
                                          for r in rows)
        cols = ("unit", "model", *(("group",) if grouped else ()), "tests", "latest",
                *(("regime",) if regimes else ()), "date", "status",
                *(("no-go in",) if ahead else ()))
        flagged, cells = [], []
        for r in rows:
            model = Path(str(r["model"])).name
            count = str(r["tests"]) if not r["isolations"] else f"{r['isolations']} iso"
            status = status_text(str(r["status"])) if r["status"] else "—"
            if r["baseline_flags"]:
                status += " [yellow]⚠[/]"
            if r["group_flags"]:
                status += " [yellow]⚑[/]"
            cells.append((escape(str(r["unit"])), escape(model),
                          *((escape(str(r["group"] or "—")),) if grouped else ()), count,
                          escape(Path(str(r["latest_source"] or "—")).name),
                          *((escape(str(r["latest_regime"] or "—")),) if regimes else ()),
                          str(r["latest_date"] or "—")[:10], status,
                          *((remaining_text(r["forecast"], r["forecast_reason"]),)
                            if ahead else ())))
            if r["baseline_flags"]:
                flagged.append(str(r["unit"]))
        # a narrow terminal cuts the latest record's file name (the history shows it
        # whole), then folds a long unit name (never cut: EMA-1… could be EMA-10), the
        # model, the regime, the group, each at a few characters, not at one; then
        # leaves out the latest record, the model, the regime (and says so)
        kept = {"unit": min(8, max([4, *(len(str(r["unit"])) for r in rows)])), "status": 6,
                "date": 10, "tests": 5,
                "no-go in": max([8, *(len(c[-1]) for c in cells)]) if ahead else 0}
        widths, hidden = fitted_widths(cols, cells, out.width, [
            ("latest", 12), ("unit", 12), ("model", 8), ("regime", 8), ("group", 8),
            ("latest", 6), ("unit", 8), ("model", 6), ("regime", 6), ("group", 6),
            ("unit", 6)], kept, drop=("latest", "model", "regime", "group"))
        visible = [k for k, col in enumerate(cols) if col not in hidden]
        for k in visible:
            col = cols[k]
            folds = col in ("unit", "model", "regime", "group")
            table.add_column(col, justify="right" if col == "tests" else "left",
                             no_wrap=not folds, overflow="fold" if folds else "ellipsis",
                             min_width=kept.get(col) or None, max_width=widths.get(col))
        for row in cells:
            table.add_row(*(row[k] for k in visible))
        out.print(table)
        if hidden:
            out.print(f"{', '.join(hidden)}: left out, the terminal is {out.width} columns wide "
                      "(a wider one, COLUMNS=120, or --json shows them)", markup=False,
                      highlight=False)
        if doc["pages"] > 1:
            out.print(f"page {doc['page']} of {doc['pages']} ({doc['per_page']} units a page, "
                      f"{doc['total']} in all); --page N for another", markup=False,
                      highlight=False)
        if ahead:
            out.print("no-go in: the earliest forecast to no-go, tests (days, hours, cycles) "
                      "left, median (90 % interval; date past: its median date is before "
                      "today, the unit is due a check); `condmon forecast --unit U` for every "
                      "parameter",
                      markup=False, highlight=False, soft_wrap=True)
        if flagged:
            err.print(f"warning: baseline flagged for {', '.join(flagged)} (`condmon baseline list "
                      "--unit U` shows why)", highlight=False, markup=False, soft_wrap=True)
        for r in rows:
            for f in r["group_flags"]:
                err.print(f"⚑ {r['unit']} is unlike its group {f['group']!r}: {f['message']}",
                          highlight=False, markup=False, soft_wrap=True)
        for g, n in small.items():
            err.print(f"note: group {g!r} has {n} unit(s) with a baseline of their own; units are "
                      f"compared with their peers from {least} on", highlight=False,
                      markup=False, soft_wrap=True)


    def _stream_units(store: Any, sort: str) -> None:
        """``units --json`` of every unit, read and printed 500 units at a time."""
        from condmon.report.web_data import fleet_document

        head = fleet_document(store, sort=sort, page=1, per_page=1)

        def units() -> Any:
            page = 1
            while True:
                chunk = fleet_document(store, sort=sort, page=page, per_page=500)
                yield from chunk["units"]
                if page >= chunk["pages"]:
                    return
                page += 1

        write_json_list(units(), "units", {"page": 1, "per_page": None, "pages": 1,
                                           **{k: head[k] for k in ("matching", "total",
                                                                   "counts")}})

    @app.command("history")
    def history_cmd(
        unit: UnitOpt,
        db: DbOpt = "condmon.db",
        as_json: Annotated[bool, typer.Option("--json", help="Print the history as JSON records.")] = False,
    ) -> None:
        """Show the unit's tests (fit, status, parameter changes) or isolations."""
        import pandas as pd

        from condmon.models.registry import get_model
        from condmon.store.db import open_store

        with open_store(db, create=False) as store:
            hist = store.history(unit)
            isos = store.isolations(unit)
            model = store.unit_model(unit) or "dc-motor"
            baseline = store.latest_baseline(unit)
            names = {b.id: b.name for b in store.baselines(unit)} if len(hist) else {}
        if as_json:   # printed 200 records at a time
            from condmon.io.jsonable import frame_records

            write_json_list({"kind": kind, **d} for kind, frame in (("test", hist),
                                                                   ("isolation", isos))
                            for i in range(0, len(frame), 200)
                            for d in frame_records(frame.iloc[i:i + 200]))
            return
        name = escape(_declared_name(model))
        if len(isos):
            _print_isolations(unit, name, isos)
        if len(hist) == 0:
            if not len(isos):
                out.print(f"{escape(unit)} has no tests yet")
            return
        # the estimated parameters (derived ones, e.g. Ke = gamma Kt, move with them); a
        # regime's (Tc@forward) in its parameter's column, the regime in a column of its own
        from condmon.models.regimes import regime_key, split_key

        keyed = [c for c in hist.columns if f"{c}_se" in hist.columns]
        machine = get_model(model)
        imported = machine.indicators is not None   # its values' axis, not a fit
        listed = machine.spec.report if imported else \
            (*machine.spec.unknowns, *(f.name for f in machine.features))   # features too
        params = [p for p in listed if any(split_key(c)[0] == p for c in keyed)]
        axis = next((a for a in ("cycle", "hours") if imported and a in hist
                     and hist[a].notna().any()), "")
        regimes = bool(hist["regime"].notna().any())
        dated = hist["test_date"].notna().any()
        # tests a day apart or more show their day; several in a day, their time too
        # (to the second when several start within a minute: a rig's cycles)
        given = hist["test_date"].dropna()
        stamp = next((f for f in ("%Y-%m-%d", "%Y-%m-%d %H:%M")
                      if given.dt.strftime(f).nunique() == given.nunique()),
                     "%Y-%m-%d %H:%M:%S")
        wide = len(datetime(2000, 1, 1).strftime(stamp))
        cols = ("#", *(("date",) if dated else ()), "source", *(("regime",) if regimes else ()),
                axis or "fit %", "status", *params)
        cells = []
        moved = dict.fromkeys(params, 0.0)   # each parameter's largest change shown [%]
        notes = []
        for tid, r in hist.iterrows():
            status = r["status"]
            shown = (status_text(status) if status in ("go", "advisory", "no-go", "retest")
                     else {"rejected": "[red]rejected[/]", "excluded": "[dim]excluded[/]"}.get(
                         status, escape(str(status))))
            label = str(r["regime"]) if pd.notna(r["regime"]) else ""
            own = [x.strip() for x in label.split(";") if x.strip()] or [""]
            changes = []
            for p in params if status != "excluded" else ():
                found = [r[f"{regime_key(p, g)}_change"] for g in own
                         if f"{regime_key(p, g)}_change" in r
                         and pd.notna(r[f"{regime_key(p, g)}_change"])]
                changes.append(f"{found[0]:+.1f}" if found else "")
                if found:
                    moved[p] = max(moved[p], abs(float(found[0])))
            changes += [""] * (len(params) - len(changes))
            fit = (f"{r[axis]:g}" if axis and pd.notna(r[axis]) else
                   f"{r['fit_percent']:.1f}" if pd.notna(r["fit_percent"]) else "—")
            when = ((r["test_date"].strftime(stamp) if pd.notna(r["test_date"]) else "—",)
                    if dated else ())
            cells.append((str(tid), *when, escape(Path(str(r["source"])).name),
                          *((escape(label or "—"),) if regimes else ()), fit, shown,
                          *changes))
            if status == "excluded":
                notes.append(f"#{tid} excluded: {r['excluded_reason']}")
            elif isinstance(r["summary"], str) and r["role"] == "check":
                ref = names.get(int(r["baseline_id"])) if pd.notna(r["baseline_id"]) else None
                against = (f" (against {ref.replace(':', ' ', 1)})"
                           if ref and ref.startswith(("group:", "unit:")) else "")
                notes.append(f"#{tid} {r['summary']}{against}")
            elif not r["accepted"]:
                notes.append(f"#{tid} rejected: {r['reason']}")
        # fits 80 columns with a date and five parameters; a narrower terminal cuts the
        # record's name, then leaves out the parameters that moved least, and says which
        least = {"#": 3, "fit %": 5, "cycle": 5, "hours": 5, "status": 8, "date": wide,
                 "source": 8,
                 **{p: 5 for p in params}}
        room, hidden = fitted_widths(cols, cells, out.width, [("source", 8)], least,
                                     drop=sorted(params, key=lambda p: moved[p]))
        table = Table(box=box.SIMPLE_HEAD, padding=(0, 1), pad_edge=False, collapse_padding=True)
        visible = [k for k, col in enumerate(cols) if col not in hidden]
        for k in visible:
            col = cols[k]
            table.add_column(col, justify="left" if col in ("source", "status", "date", "regime")
                             else "right", no_wrap=True, overflow="ellipsis",
                             min_width=least.get(col),
                             max_width={"source": min(room.get("source", 10**6),
                                                      max(10 if dated else 14, out.width - 70)),
                                        "date": wide}.get(col))
        for row in cells:
            table.add_row(*(row[k] for k in visible))
        out.print(f"History of {escape(unit)} ({name}): change against the "
                  "baseline [%]", highlight=False)
        out.print(table)
        if hidden:
            out.print(f"{', '.join(hidden)}: left out (they moved least), the terminal is "
                      f"{out.width} columns wide (a wider one, COLUMNS=120, or --json shows "
                      "them)", markup=False, highlight=False)
        for line in notes:
            out.print(line, highlight=False, markup=False)
        if baseline is not None:
            out.print(f"baseline {baseline.name!r} v{baseline.version} (N = {baseline.baseline.n}): "
                      + id_runs(baseline.test_ids), highlight=False, markup=False)
            gone = [int(i) for i in baseline.test_ids
                    if i in hist.index and hist.loc[i, "status"] == "excluded"]
            if gone:   # excluded since, with too few left for a new version
                out.print(f"  {id_runs(gone)} excluded since: this version no longer stands; "
                          "the checks above were judged against it, and new checks are "
                          "refused until healthy tests are added (baseline add)",
                          highlight=False, markup=False)
            print_flags(baseline.flags, unit)


    @app.command("report")
    def report_cmd(
        out_dir: Annotated[Path, typer.Option("--out", help="Folder for the HTML pages and PNG figures.")],
        unit: Annotated[Optional[str], typer.Option("--unit", help="Only this unit's page (default: every unit); the fleet index is refreshed either way.")] = None,
        db: DbOpt = "condmon.db",
        monitor: Annotated[Optional[Path], typer.Option(help="Monitor breakpoints TOML (default: each unit's model's).")] = None,
    ) -> None:
        """Write HTML pages (a fleet index and a page per unit) with trend, fit and symptom figures."""
        from condmon.monitor.fuzzy import load_monitor_config
        from condmon.report.html import write_fleet_report
        from condmon.store.db import open_store

        cfg = load_monitor_config(monitor) if monitor is not None else None
        with open_store(db, create=False) as store:  # read only: never makes a database
            if unit is not None:
                store.unit_id(unit)  # an unknown unit: the error names the known ones
            total = 1 if unit is not None else len(store.units())
            with progress() as prog:
                task = prog.add_task("writing pages", total=total)

                def step(done: int, _total: int, name: str) -> None:
                    prog.update(task, completed=done, description=escape(name[:40]))

                rep = write_fleet_report(store, out_dir, None if unit is None else [unit],
                                         monitor=cfg, progress=step)
        for p in rep.pages[:20]:
            figs = f"{len(p.figures)} figure{'s' if len(p.figures) != 1 else ''}"
            out.print(f"wrote {p.html} ({figs}) for {p.unit}", markup=False,
                      highlight=False, soft_wrap=True)
        if len(rep.pages) > 20:
            out.print(f"... and {len(rep.pages) - 20} more unit pages in {Path(out_dir)}",
                      markup=False, highlight=False, soft_wrap=True)
        out.print(f"wrote {len(rep.pages)} unit page{'s' if len(rep.pages) != 1 else ''} and the "
                  f"fleet index {rep.index}", markup=False, highlight=False, soft_wrap=True)


def _print_isolations(unit: str, model: str, isos: Any) -> None:
    import pandas as pd

    table = Table(title=escape(f"Isolations of {unit} ({model})"), box=box.SIMPLE_HEAD)
    for col in ("#", "date", "source", "status", "detected", "isolated"):
        table.add_column(col, no_wrap=col != "isolated", overflow="fold")
    for iid, r in isos.iterrows():
        det = f"{r['detection_time']:.2f} s" if pd.notna(r["detection_time"]) else "—"
        status = "[dim]excluded[/]" if r["excluded"] else status_text(str(r["status"]))
        table.add_row(f"i{iid}", f"{r['date']:%Y-%m-%d %H:%M}",
                      escape(Path(str(r["source"])).name), status, det,
                      escape(", ".join(r["isolated"]) or "—"))
    out.print(table)
    for iid, r in isos.iterrows():
        out.print(f"i{iid} {r['statement']}", highlight=False, markup=False)


def _declared_name(model: str) -> str:
    """A model's declared name (a declaration's ``name``; its file name when it
    cannot be read)."""
    from condmon.errors import CondmonError
    from condmon.models.registry import get_model

    try:
        return get_model(model).name
    except CondmonError:
        return Path(model).name
