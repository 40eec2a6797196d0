"""Content hashes: the same data in any file is the same test; other data is not."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from condmon.io.digest import content_hash
from condmon.io.readers import read_record

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
