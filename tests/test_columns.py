"""The plain-CSV reader of the start-up path: the same numbers as the pandas
reader, or None so that the pandas reader reads (or refuses) the file."""

from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from condmon.errors import CondmonError
from condmon.identify import estimate
from condmon.io.columns import Columns, read_plain_csv
from condmon.io.digest import content_hash, fingerprint
from condmon.io.readers import read_record
from condmon.io.records import write_record
from condmon.simulate import simulate_actuator
from condmon.workflows.records import EstimateOptions, record_key

FAST = settings(deadline=None, derandomize=True, database=None, max_examples=150,
                suppress_health_check=[HealthCheck.too_slow])


def _same(plain: Columns, frame: pd.DataFrame) -> None:
    assert plain.columns == [str(c) for c in frame.columns]
    assert len(plain) == len(frame)
    for name in plain.columns:
        ref = frame[name].to_numpy(dtype=np.float64)
        assert np.array_equal(plain[name].view(np.int64), ref.view(np.int64)), name


def _write(tmp: Path, text: str, name: str = "r.csv") -> Path:
    path = tmp / name
    path.write_bytes(text.encode("utf-8"))
    return path


@pytest.fixture(scope="module")
def record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_record(simulate_actuator(seed=5), tmp_path_factory.mktemp("plain") / "act.csv")


def test_a_written_record_reads_plain_and_to_the_bit(record: Path) -> None:
    plain = read_plain_csv(record)
    assert plain is not None and plain.attrs == {"source": str(record)}
    _same(plain, read_record(record))


def test_the_record_key_and_the_estimate_are_the_pandas_readers(record: Path) -> None:
    plain, frame = read_plain_csv(record), read_record(record)
    assert plain is not None
    assert content_hash(plain) == content_hash(frame)
    assert fingerprint(plain) == fingerprint(frame)
    a, b = estimate(plain), estimate(frame)
    assert a.parameters == b.parameters and a.std_errors == b.std_errors
    res, key = EstimateOptions().run(record)
    assert res.parameters == b.parameters
    assert key == record_key(frame, record)


def test_a_mapping_renames_as_the_pandas_reader(tmp_path: Path) -> None:
    path = _write(tmp_path, "time,V,volts,I,omega\n0,9,1.5,2,3\n0.5,9,2.5,2,4\n")
    mapping = {"t": "time", "V": "volts"}  # "V" of the file is shadowed
    plain = read_plain_csv(path, mapping)
    assert plain is not None and plain.columns == ["t", "V", "I", "omega"]
    _same(plain, read_record(path, mapping))
    assert read_plain_csv(path, {"t": "absent"}) is None
    assert read_plain_csv(path, {"t": "time", "x": "time"}) is None


@pytest.mark.parametrize("text", [
    "t;V\n0,0;1,5\n0,1;2,5\n",                       # semicolons, decimal comma
    "t\tV\n0.0\t1.5\n",                              # tabs
    '"t","V"\n0.0,1.5\n',                            # quotes
    "t,V\n0.0,1.5\n\n0.1,2.5\n",                     # a blank line
    "t,V\n0.0,1.5\n0.1\n",                           # a short row
    "t,V\n0.0,\n0.1,2.5\n",                          # an empty field
    "t,V\n0.0,nan\n0.1,2.5\n",                       # nan
    "t,V\n0.0,inf\n0.1,2.5\n",                       # inf
    "t,V\n0.0, 1.5\n0.1,2.5\n",                      # a space
    "t,V\n0.0,1_000\n0.1,2.5\n",                     # a digit separator
    "t,V\n0.0,+1.5\n0.1,2.5\n",                      # a plus sign
    "t,V\n2026-01-01 10:00:00,1.5\n2026-01-01 10:00:01,2.5\n",  # dates
    "t,V,V\n0.0,1.5,2\n",                            # a name twice
    "t,,V\n0.0,1.5,2\n",                             # a name missing
    "0.0,1.5\n0.1,2.5\n",                            # no header
    "t,V\n",                                         # no rows
    "t\n0.0\n0.1\n",                                 # one column
    "t,V\n0.0,123456789012345678901\n0.1,2\n",       # an integer beyond int64
])
def test_what_is_not_plain_is_left_to_the_pandas_reader(tmp_path: Path, text: str) -> None:
    assert read_plain_csv(_write(tmp_path, text)) is None


def test_other_files_are_left_to_the_pandas_reader(tmp_path: Path) -> None:
    assert read_plain_csv(tmp_path / "missing.csv") is None
    assert read_plain_csv(_write(tmp_path, "t,V\n0,1\n", "r.txt")) is None
    assert read_plain_csv(_write(tmp_path, "", "empty.csv")) is None
    latin = tmp_path / "latin.csv"
    latin.write_bytes("t,V\xb0\n0,1\n".encode("latin-1"))
    assert read_plain_csv(latin) is None


def test_a_record_beyond_the_limits_is_left_to_the_pandas_reader(
        record: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONDMON_MAX_SAMPLES", "100")
    assert read_plain_csv(record) is None
    with pytest.raises(CondmonError, match="CONDMON_MAX_SAMPLES"):
        read_record(record)


def test_a_plain_record_becomes_a_frame_with_its_attrs(record: Path) -> None:
    plain = read_plain_csv(record)
    assert plain is not None
    frame = plain.to_frame()
    assert frame.attrs == plain.attrs and list(frame.columns) == plain.columns
    _same(plain, frame)


_NUMBERS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.floats(allow_nan=False, allow_infinity=False).map(lambda v: f"{v:.17g}"),
    st.integers(-10**20, 10**20).map(str),
    st.sampled_from(["0", "-0", "-0.0", ".5", "5.", "1e5", "1E-5", "1e+300", "2.5e-310",
                     "0.1", "00012", "9007199254740993", "123456789012345678"]),
)
_FIELD = st.one_of(_NUMBERS, st.sampled_from(["1,5", "", "nan", " 1", "1 ", "+1", "x", "1e",
                                              "-", "0x10", "1_0", "٣"]))


@st.composite
def csv_texts(draw: st.DrawFn, fields: st.SearchStrategy[str] = _FIELD) -> str:
    width = draw(st.integers(1, 4))
    names = draw(st.lists(st.sampled_from(["t", "V", "I", "omega", "x y", "1", ""]),
                          min_size=width, max_size=width))
    rows = draw(st.lists(st.lists(fields, min_size=width, max_size=width), min_size=0,
                         max_size=6))
    end = draw(st.sampled_from(["\n", "\r\n"]))
    return end.join([",".join(names), *(",".join(r) for r in rows)]) + end


@FAST
@given(st.one_of(csv_texts(), csv_texts(_NUMBERS)))
def test_plain_files_read_as_pandas_reads_them(text: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(Path(tmp), text)
        plain = read_plain_csv(path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                frame = read_record(path)
            except CondmonError:
                assert plain is None, text
                return
        if plain is not None:
            _same(plain, frame)


@pytest.mark.parametrize("frame,whole", [
    (pd.DataFrame({"t": [0.0, 0.1, 0.2], "V": [1.0, 2.0, 3.0]}), True),
    (pd.DataFrame({"t": [0.0, 0.1, 0.2], "n": np.array([1, 2, 2**53 + 1])}), True),  # an int
    (pd.DataFrame({"t": np.arange(3, dtype=np.int64), "V": [1, 2, 3]}), False),     # ints only
    (pd.DataFrame({"t": [0.0, 0.1, 0.2], "V": np.ones(3, dtype=np.float32)}), True),
    (pd.DataFrame({"t": np.ones(3, dtype=np.float32)}), False),
    (pd.DataFrame({"t": [0.0, 0.1, 0.2], "V": ["a", "b", "c"]}), False),
    (pd.DataFrame({"t": [0.0, 0.1, 0.2], "V": [True, False, True]}), False),
    (pd.DataFrame([[0.0, 1.0], [0.1, 2.0]], columns=["t", "t"]), False),
    (pd.DataFrame([[0.0, 1.0], [0.1, 2.0]], columns=["t", 3]), False),
])
def test_a_frame_becomes_columns_only_when_it_converts_as_its_columns_do(
        frame: pd.DataFrame, whole: bool) -> None:
    """A frame is taken whole when its columns' common dtype is float64 (an
    integer or float32 column beside float64 ones converts exactly as the
    column-by-column path converts it); otherwise it is returned unchanged."""
    from condmon.io.columns import as_columns, column_values

    frame.attrs["source"] = "rig.csv"
    out = as_columns(frame)
    assert isinstance(out, Columns) is whole
    if whole:
        assert out.attrs == {"source": "rig.csv"}
        for name in frame.columns:
            np.testing.assert_array_equal(out[name], column_values(frame, name))
            assert out[name].dtype == np.float64
    else:
        assert out is frame
