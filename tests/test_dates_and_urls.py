"""Test dates a user gives, and database URLs in messages."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.errors import DataError
from condmon.io.dates import parse_date
from condmon.store.engine import StoreError, redact, store_error


def test_iso_dates_are_utc_and_others_refused() -> None:
    assert parse_date("2026-03-01T14:30") == datetime(2026, 3, 1, 14, 30, tzinfo=timezone.utc)
    assert parse_date("2026-03-01T14:30+02:00") == datetime(2026, 3, 1, 12, 30,
                                                            tzinfo=timezone.utc)
    for bad in ("01/03/2026", "yesterday", "1850-01-01"):
        with pytest.raises(DataError, match="is not a date"):
            parse_date(bad)


def test_a_date_in_the_future_is_refused() -> None:
    soon = datetime.now(timezone.utc) + timedelta(hours=2)  # clocks a little apart: fine
    assert parse_date(soon) == soon
    later = (datetime.now(timezone.utc) + timedelta(days=400)).strftime("%Y-%m-%d")
    with pytest.raises(DataError, match="in the future"):
        parse_date(later)
    with pytest.raises(DataError, match="manifest row 3: .* in the future"):
        parse_date(datetime.now(timezone.utc) + timedelta(days=3), "manifest row 3")


def test_the_cli_refuses_a_future_date_before_storing(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.simulate import simulate_actuator

    rec = tmp_path / "r.csv"
    simulate_actuator(seed=3).to_csv(rec, index=False)
    db = tmp_path / "h.db"
    assert main(["baseline", "add", str(rec), "--unit", "U", "--db", str(db),
                 "--date", "2099-01-01"]) == 2
    err = capsys.readouterr().err
    assert "in the future" in err and len(err.strip().splitlines()) == 1


def test_passwords_never_printed() -> None:
    url = "postgresql://ops:s3cr3t@db.example:5432/condmon"
    assert redact(url) == "postgresql://ops:***@db.example:5432/condmon"
    assert redact("postgresql://ops@db/condmon") == "postgresql://ops@db/condmon"
    assert redact("/data/a:b@c.db") == "/data/a:b@c.db"  # a file name is left alone
    err = store_error(RuntimeError(f"connection to {url} failed"), url)
    assert isinstance(err, StoreError) and "s3cr3t" not in str(err) and "ops:***@" in str(err)


@pytest.mark.parametrize("extra", [["--model", "no-such-model"], ["--date", "03/01/2026"],
                                   ["MISSING"]])
def test_a_failed_baseline_add_leaves_no_new_history(tmp_path: Path, extra: list[str],
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.simulate import simulate_actuator

    rec = tmp_path / "r.csv"
    simulate_actuator(seed=4).to_csv(rec, index=False)
    db = tmp_path / "new.db"
    args = [str(tmp_path / "missing.csv")] if extra == ["MISSING"] else [*extra]
    assert main(["baseline", "add", str(rec), *args, "--unit", "U", "--db", str(db)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not db.exists()


_FORMATS = ("%m-%d-%Y-%I-%M-%S %p", "%Y%m%d-%H%M%S", "%Y-%m-%dT%H-%M-%S", "%d%b%y_%H%M%S",
            "%Y_%j_%H%M%S")


@pytest.mark.parametrize("fmt", _FORMATS)
def test_a_start_time_written_into_any_file_name_reads_back(fmt: str) -> None:
    """Property: a time written with ``fmt`` among other text of a file's name
    (letters, digits and separators before and after) reads back to the second
    (a two-digit year within strptime's window, 1969-2068)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from condmon.io.dates import time_in_name

    text = st.text(alphabet="ABCxyz_ ._", max_size=12)
    last = datetime(2068, 12, 31) if "%y" in fmt else datetime(2099, 12, 31)

    @settings(max_examples=150, deadline=None)
    @given(st.datetimes(min_value=datetime(1971, 1, 1), max_value=last),
           text, text, st.integers(0, 999))
    def check(when: datetime, before: str, after: str, run: int) -> None:
        when = when.replace(microsecond=0)
        name = f"Base_{run}_{before}{when.strftime(fmt)}{after}.txt"
        assert time_in_name(name, fmt) == when.replace(tzinfo=timezone.utc), name

    check()
