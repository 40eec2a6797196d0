"""A history outlives its declaration files: the unit keeps their text.

A unit monitored with a user's declaration keeps the declaration and its
``[monitor]`` files in the history. After the files are moved, ``history``,
``report`` and ``forecast`` still work; ``check --model NEW.toml`` with the
same equations, parameters and rules re-points the unit (audited), another
declaration is refused, and ``condmon unit set-model`` re-points on purpose.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.models.bundle import declaration_bundle

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "examples" / "template.toml"
RULES = ROOT / "src" / "condmon" / "data" / "monitor.toml"


def _declaration(folder: Path) -> Path:
    """The template with its [monitor] breakpoints in a parent folder's file."""
    folder.mkdir(parents=True)
    text = TEMPLATE.read_text()
    (folder.parent / "breakpoints.toml").write_text(
        "[breakpoints]\n" + "".join(f"{p} = {{ r1 = 20.0, r2 = 40.0 }}\n" for p in "mck"))
    path = folder / "msd.toml"
    path.write_text(text + '\n[monitor]\nbreakpoints = "../breakpoints.toml"\n')
    return path


def _unit_in_sqlite(tmp_path: Path, records: list[str], monkeypatch: pytest.MonkeyPatch
                    ) -> tuple[Path, Path]:
    """Unit U's baseline in a SQLite history, with its declaration in ``site/``."""
    monkeypatch.setenv("CONDMON_CACHE", str(tmp_path / "cache"))
    decl = _declaration(tmp_path / "site" / "models")
    db = tmp_path / "h.db"
    assert main(["baseline", "add", *records[:3], "--unit", "U", "--model", str(decl),
                 "--db", str(db)]) == 0
    return db, decl


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    tmp = tmp_path_factory.mktemp("msd-records")
    out = []
    for seed in range(1, 7):
        p = tmp / f"r{seed}.csv"
        assert main(["simulate", "plant", str(TEMPLATE), "--out", str(p), "--seed",
                     str(seed), "--duration", "4"]) == 0
        out.append(str(p))
    return out


def test_a_bundle_means_the_same_whatever_its_comments_and_names(tmp_path: Path) -> None:
    a = _declaration(tmp_path / "a" / "m")
    b = tmp_path / "b" / "other.toml"
    b.parent.mkdir(parents=True)
    b.write_text("# a copy with a comment\n" + a.read_text().replace(
        "../breakpoints.toml", "bp.toml"))
    shutil.copy(a.parent.parent / "breakpoints.toml", b.parent / "bp.toml")
    assert declaration_bundle(a).digest == declaration_bundle(b).digest
    (b.parent / "bp.toml").write_text(
        (a.parent.parent / "breakpoints.toml").read_text().replace("m = { r1 = 20.0", "m = { r1 = 21.0"))
    assert declaration_bundle(a).digest != declaration_bundle(b).digest
    bundle = declaration_bundle(a)
    assert bundle.main == "_/msd.toml" and "breakpoints.toml" in bundle.files


def test_a_moved_declaration_keeps_its_unit_working(
        store_url: str, tmp_path: Path, records: list[str], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("CONDMON_CACHE", str(tmp_path / "cache"))
    decl = _declaration(tmp_path / "site" / "models")
    db = ["--db", store_url]
    assert main(["baseline", "add", *records[:3], "--unit", "U", "--model", str(decl),
                 *db]) == 0
    for r in records[3:5]:
        assert main(["check", r, "--unit", "U", *db]) == 0
    shutil.move(tmp_path / "site", tmp_path / "moved")     # the files move
    capsys.readouterr()
    assert main(["history", "--unit", "U", *db]) == 0
    assert "History of U (my-machine)" in capsys.readouterr().out
    assert main(["report", "--unit", "U", "--out", str(tmp_path / "report"), *db]) == 0
    assert main(["forecast", "--unit", "U", *db]) in (0, 2)
    assert "declaration file not found" not in capsys.readouterr().err
    assert main(["units", *db]) == 0
    assert "my-machine" in capsys.readouterr().out
    # the same declaration at its new path: accepted and re-pointed
    new = tmp_path / "moved" / "models" / "msd.toml"
    assert main(["check", records[5], "--unit", "U", "--model", str(new), *db]) == 0
    capsys.readouterr()
    assert main(["audit", "--unit", "U", *db]) == 0
    log = capsys.readouterr().out
    assert "model re-pointed" in log and "the same declaration at a new path" in log
    # another declaration is refused, naming how to re-point on purpose
    other = tmp_path / "moved" / "models" / "other.toml"
    other.write_text(new.read_text().replace("value = 5.0", "value = 6.0"))
    assert main(["check", records[0], "--unit", "U", "--model", str(other), "--dry-run",
                 *db]) == 2
    err = capsys.readouterr().err
    assert "equations, parameters or rules differ" in err and "unit set-model U" in err
    assert main(["unit", "set-model", "U", str(other), *db]) == 0
    assert "differs from the one the unit's tests were judged with" in capsys.readouterr().out


def test_a_unit_whose_file_is_gone_and_not_kept_says_how_to_mend(
        tmp_path: Path, records: list[str], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A history written before declarations were kept (v11) names the fix."""
    import sqlite3

    db, _ = _unit_in_sqlite(tmp_path, records, monkeypatch)
    with sqlite3.connect(db) as c:
        c.execute("UPDATE units SET model_digest = NULL")
    shutil.rmtree(tmp_path / "site")
    capsys.readouterr()
    assert main(["check", records[3], "--unit", "U", "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert "declaration file not found" in err and "condmon unit set-model UNIT FILE" in err


def test_a_v11_history_keeps_the_declarations_still_found(
        tmp_path: Path, records: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Opening a v11 history adds ``units.model_digest`` and keeps each unit's
    declaration whose file is still where it was."""
    import sqlite3

    from condmon.store.db import open_store

    db, decl = _unit_in_sqlite(tmp_path, records, monkeypatch)
    with sqlite3.connect(db) as c:
        c.execute("ALTER TABLE units DROP COLUMN model_digest")
        c.execute("DROP TABLE declarations")
        c.execute("UPDATE condmon_meta SET value = '11' WHERE key = 'schema_version'")
    with open_store(str(db)) as store:
        assert store.schema_version == 13
        assert store.unit_declaration("U")[1] == declaration_bundle(decl).digest
    shutil.rmtree(tmp_path / "site")
    with open_store(str(db)) as store:
        kept = Path(str(store.unit_model("U")))
    assert kept.is_file() and kept.is_relative_to(tmp_path / "cache")


def test_a_declared_model_s_fleet_prior_finds_its_peers(
        tmp_path: Path, records: list[str]) -> None:
    """Peers were looked up by the unit's declaration file while the history
    keeps the model's declared name: 'no fleet history' with failed units of
    the same model. Two units whose files sit at different paths are peers."""
    from condmon.store.db import open_store
    from condmon.store.forecasts import FleetHistory
    from condmon.workflows.checks import check_test
    from condmon.workflows.monitoring import add_baseline_tests
    from condmon.workflows.records import EstimateOptions

    paths = []
    for where in ("a", "b"):
        p = tmp_path / where / "msd.toml"
        p.parent.mkdir()
        shutil.copy(TEMPLATE, p)
        paths.append(p)
    worn = []
    for k, damping in enumerate((6.5, 8.0, 10.0)):
        p = tmp_path / f"worn{k}.csv"
        assert main(["simulate", "plant", str(TEMPLATE), "--out", str(p), "--seed",
                     str(20 + k), "--duration", "4", "--fault", f"c={damping}@0s"]) == 0
        worn.append(str(p))
    with open_store(str(tmp_path / "h.db")) as store:
        for unit, path in (("OLD1", paths[0]), ("OLD2", paths[1]), ("NEW", paths[1])):
            opts = EstimateOptions(model=str(path))
            add_baseline_tests(store, unit, records[:3], opts)
            if unit != "NEW":
                for i, rec in enumerate(worn):
                    check_test(store, unit, rec, opts, test_date=f"2026-01-0{2 + i}")
        assert store.unit_model_name("OLD1") == store.unit_model_name("NEW") == "my-machine"
        assert store.degraded_among(["OLD1", "OLD2", "NEW"]) == {"OLD1", "OLD2"}
        fleet = FleetHistory(store)
        assert sorted(fleet.learning_peers("NEW")) == ["OLD1", "OLD2"]
        assert fleet.peer_count("NEW") == 2
