"""Content hashes: the same data in any file is the same test; other data is not."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from condmon.io.digest import content_hash, fingerprint, same_content
from condmon.io.readers import read_record

if TYPE_CHECKING:
    from conftest import RecordFiles

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False,
                   width=64)


@st.composite
def records(draw: st.DrawFn) -> pd.DataFrame:
    n = draw(st.integers(min_value=3, max_value=40))
    cols = draw(st.lists(st.sampled_from(["V", "I", "omega", "yd", "ud"]), min_size=1,
                         max_size=4, unique=True))
    df = pd.DataFrame({"t": np.arange(n) * 1e-3})
    for c in cols:
        df[c] = draw(arrays(np.float64, n, elements=finite))
    return df


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(df=records(), data=st.data())
def test_copies_share_the_hash_and_changes_do_not(tmp_path: Path, df: pd.DataFrame,
                                                  data: st.DataObject) -> None:
    h = content_hash(df)
    shuffled = df[list(reversed(df.columns))]
    assert content_hash(shuffled) == h
    csv, crlf, parquet = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.parquet"
    df.to_csv(csv, index=False)
    crlf.write_bytes(csv.read_bytes().replace(b"\n", b"\r\n") + b"\r\n")
    df.to_parquet(parquet)
    for path in (csv, crlf, parquet):
        assert content_hash(read_record(path)) == h, path
    # one value changed beyond the last digits, a row dropped: another test
    col = data.draw(st.sampled_from([c for c in df.columns if c != "t"]))
    row = data.draw(st.integers(min_value=0, max_value=len(df) - 1))
    other = df.copy()
    other.loc[row, col] = other.loc[row, col] * (1 + 1e-6) + 1e-3
    assert content_hash(other) != h
    assert content_hash(df.iloc[:-1]) != h


def test_copies_rounded_otherwise_or_with_other_columns_are_the_same_test(
        tmp_path: Path) -> None:
    """float32 Parquet, a re-export at 12 and at 7 digits, an extra column, a copy
    without the reference columns: recognised by their fingerprints (their
    content hashes differ); 38 other tests of the same rig are not taken for it."""
    from condmon.simulate import simulate_actuator

    a = simulate_actuator(seed=1)
    a.to_csv(tmp_path / "a.csv", index=False)
    base = fingerprint(read_record(tmp_path / "a.csv"))
    a.astype("float32").to_parquet(tmp_path / "f32.parquet")
    a.to_csv(tmp_path / "g12.csv", index=False, float_format="%.12g")
    a.to_csv(tmp_path / "g7.csv", index=False, float_format="%.7g")
    a.assign(extra=np.arange(len(a))).to_csv(tmp_path / "extra.csv", index=False)
    a.drop(columns=["yd", "ud"]).to_csv(tmp_path / "noref.csv", index=False)
    for name in ("f32.parquet", "g12.csv", "g7.csv", "extra.csv", "noref.csv"):
        assert same_content(base, fingerprint(read_record(tmp_path / name))), name
    assert sum(same_content(base, fingerprint(simulate_actuator(seed=s)))
               for s in range(2, 40)) == 0
    assert not same_content(base, fingerprint(a.iloc[:-1]))       # a row fewer
    assert not same_content(base, fingerprint(a[["t", "V"]]))     # too little in common
    assert not same_content(base, None) and not same_content(base, "not json")


@settings(max_examples=60, deadline=None)
@given(df=records(), data=st.data())
def test_a_changed_value_is_another_fingerprint(df: pd.DataFrame, data: st.DataObject) -> None:
    if len(df.columns) < 3:
        return
    fp = fingerprint(df)
    assert same_content(fp, fingerprint(df * (1.0 + 1e-10)))  # a re-export's last digits
    col = data.draw(st.sampled_from([c for c in df.columns if c != "t"]))
    other = df.copy()
    scale = max(float(other[col].abs().max()), 1.0)
    other.loc[0, col] = other.loc[0, col] + 1e-3 * scale   # the first row is sampled
    assert not same_content(fp, fingerprint(other))


def test_the_history_skips_a_float32_copy(tmp_path: Path, record_files: RecordFiles) -> None:
    from condmon.cli.main import main

    files = record_files(tmp_path, range(80, 83))
    copy = tmp_path / "h1-f32.parquet"
    pd.read_csv(files[1]).astype("float32").to_parquet(copy)
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *files, str(copy), "--unit", "U", "--db", db]) == 0
    from condmon.store import open_store

    with open_store(db, create=False) as store:
        assert len(store.history("U")) == 3
