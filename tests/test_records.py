"""Bad input is refused at the boundary with the file and the column named."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from condmon.errors import DataError, DataWarning
from condmon.identify import estimate
from condmon.io import parse_column_map, read_record, validate_record


def _write(df: pd.DataFrame, tmp_path: Path, name: str = "rec.csv") -> Path:
    p = tmp_path / name
    df.to_csv(p, index=False)
    return p


def test_missing_column_names_file_and_column(noisy_record: pd.DataFrame, tmp_path: Path) -> None:
    p = _write(noisy_record.drop(columns=["I"]), tmp_path)
    with pytest.raises(DataError, match=r"rec\.csv: missing column\(s\) 'I'"):
        estimate(read_record(p))


def test_nan_is_reported_with_its_row(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df.loc[100, "omega"] = np.nan
    with pytest.raises(DataError, match=r"column 'omega' has 1 NaN/inf value\(s\) \(an empty "
                                        r"cell, NaN, inf or a spreadsheet error such as "
                                        r"#DIV/0!\), first at row 100 \(from 0; line 102 of"):
        estimate(df, source="bench.csv")
    with pytest.raises(DataError, match=r"first at row 100 \(from 0\)$"):
        estimate(df, source="bench.mat")   # no lines in a MATLAB file or a frame


def test_values_missing_at_the_end_are_said_with_their_rows(noisy_record: pd.DataFrame) -> None:
    """Trailing empty rows (a spreadsheet's export) were said to be "mismatched
    lengths", with no row."""
    df = noisy_record.copy()
    df.loc[len(df) - 3:, ["t", "V", "I", "omega"]] = np.nan
    n = len(df)
    with pytest.raises(DataError, match=rf"rig\.csv: column 't' has no value in the record's "
                                        rf"last 3 row\(s\), from row {n - 3} \(from 0; line "
                                        rf"{n - 1} of a file with a header line\): values "
                                        rf"missing at the end, or a column shorter than the "
                                        rf"others \({n - 3} samples against {n} rows\); drop"):
        estimate(df, source="rig.csv")


def test_inf_is_refused(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df.loc[len(df) - 1, "V"] = np.inf
    with pytest.raises(DataError, match="column 'V' has 1 NaN/inf"):
        estimate(df)


def test_mismatched_lengths(noisy_record: pd.DataFrame, tmp_path: Path) -> None:
    df = noisy_record.copy()
    df.loc[3000:, "I"] = np.nan  # a shorter column in the file leaves empty cells
    p = _write(df, tmp_path)
    with pytest.raises(DataError, match=r"column 'I' has no value in the record's last 1000 "
                                        r"row\(s\), from row 3000 .* a column shorter than "
                                        r"the others \(3000 samples against 4000 rows\)"):
        estimate(read_record(p))


def test_non_increasing_time(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df.loc[10, "t"] = df.loc[9, "t"]
    with pytest.raises(DataError, match="column 't' is not increasing at row 10"):
        estimate(df)


def test_non_uniform_time(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df.loc[2000:, "t"] += 0.0005
    with pytest.raises(DataError, match=r"not uniformly sampled: jitter 50 % .* at row 2000"):
        estimate(df)


def test_non_numeric_column(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy().astype({"V": object})
    df.loc[5, "V"] = "n/a"
    with pytest.raises(DataError, match="column 'V' is not numeric \\(row 5: 'n/a'\\)"):
        estimate(df)


def test_too_few_samples(noisy_record: pd.DataFrame) -> None:
    with pytest.raises(DataError, match="too few"):
        estimate(noisy_record.iloc[:40])


def test_constant_input_has_no_excitation(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df["V"] = 3.0
    with pytest.raises(DataError, match="column 'V' is constant: no excitation"):
        estimate(df)


def test_saturated_input_warns(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df["V"] = df["V"].clip(-1.0, 1.0)
    with pytest.warns(DataWarning, match="sits at its extreme values"):
        estimate(df)


def test_healthy_record_does_not_warn(noisy_record: pd.DataFrame) -> None:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        estimate(noisy_record)


def test_column_mapping_round_trip(noisy_record: pd.DataFrame, tmp_path: Path) -> None:
    df = noisy_record.rename(columns={"V": "volts", "I": "amps"})
    p = _write(df, tmp_path, "mapped.parquet".replace("parquet", "csv"))
    rec = read_record(p, parse_column_map("V=volts,I=amps"))
    assert estimate(rec).accepted
    with pytest.raises(DataError, match=r"column mapping names \['watts'\] not in the file"):
        read_record(p, {"V": "watts"})


def test_parquet_records(noisy_record: pd.DataFrame, tmp_path: Path) -> None:
    p = tmp_path / "rec.parquet"
    noisy_record.to_parquet(p, index=False)
    assert estimate(read_record(p)).accepted


def test_unknown_file_type(tmp_path: Path) -> None:
    p = tmp_path / "rec.xlsx"
    p.write_text("x")
    with pytest.raises(DataError, match=r"unknown file type '\.xlsx'; allowed: \.csv, \.parquet, "
                                        r"\.pq, \.txt, \.tsv, \.mat, \.tdms"):
        read_record(p)


def test_bad_column_map() -> None:
    with pytest.raises(DataError, match="CANONICAL=FILE_COLUMN"):
        parse_column_map("V:volts")


def test_validate_record_returns_float64_columns(noisy_record: pd.DataFrame) -> None:
    rec = validate_record(noisy_record, ("V", "I"))
    assert rec.dt == pytest.approx(1e-3)
    assert rec["V"].dtype == np.float64 and len(rec) == 4000


def test_the_median_and_the_level_count_are_numpys() -> None:
    """The time base's median and the saturation check's level count, computed
    without np.median / np.unique (which import numpy.ma at start-up)."""
    from condmon.io.records import _distinct, _median

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 7, 100, 101, 4000):
        x = rng.normal(size=n) * 10.0 ** rng.uniform(-5, 5)
        assert _median(x) == float(np.median(x))
        assert _distinct(np.round(x, 1)) == np.unique(np.round(x, 1)).size
    assert _median(np.array([1e308, 1.5e308, 1.7e308])) == 1.5e308  # no overflow
    assert _distinct(np.array([0.0, -0.0, 1.0])) == 2


def test_a_frame_s_time_spans_or_date_times_are_read_as_seconds(
        noisy_record: pd.DataFrame) -> None:
    """A notebook user's t as Timedelta or Timestamp read as nanoseconds: the
    interval "1e+06 s" or the values "beyond 1e+15"."""
    plain = estimate(noisy_record)
    spans = noisy_record.assign(t=pd.to_timedelta(noisy_record["t"], unit="s"))
    stamps = noisy_record.assign(t=pd.Timestamp("2026-11-29 08:00")
                                 + pd.to_timedelta(noisy_record["t"], unit="s"))
    for frame in (spans, stamps):
        got = estimate(frame)
        assert got.parameters == pytest.approx(plain.parameters, rel=1e-9)


def test_names_that_carry_their_units_get_the_column_map_to_write(
        noisy_record: pd.DataFrame) -> None:
    named = noisy_record.rename(columns={"t": "t [s]", "V": "V [V]", "I": "I (A)"})
    with pytest.raises(DataError, match=re.escape(
            "missing column(s) 't', 'V', 'I'; the record has ['t [s]', 'V [V]', 'I (A)', "
            "'omega', 'position', 'yd', 'ud'] (their names carry units: --columns "
            "'t=t [s],V=V [V],I=I (A)' (check each unit is the model's))")):
        estimate(named)
