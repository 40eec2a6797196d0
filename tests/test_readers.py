"""Records from real acquisition files: MATLAB (v5, v7.3), TDMS, European CSV, text.

Every format gives the same DataFrame under canonical names, and every problem
is one DataError line naming the file: never a parser's own exception.
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from nptdms import ChannelObject, TdmsWriter

from condmon.errors import CondmonWarning, DataError, DataWarning
from condmon.io import READABLE_SUFFIXES, check_time_base, parse_column_map, read_record, \
    validate_record
from condmon.io.delimited import sniff_dialect

EMPS = Path("/work/shared/external/emps/DATA_EMPS.mat")
N = 200
DT = 1e-3


def _signals(n: int = N) -> dict[str, np.ndarray[Any, Any]]:
    t = np.arange(n) * DT
    return {"t": t, "V": np.sin(2 * np.pi * 5 * t), "I": 0.1 * np.cos(2 * np.pi * 5 * t)}


def _read_quiet(path: Path, columns: dict[str, str] | None = None) -> pd.DataFrame:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a reader that warns where it should not fails
        return read_record(path, columns)


# --------------------------------------------------------------------------- MATLAB v5


def test_mat_v5_vectors_are_columns_scalars_are_constants(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig.mat"
    scipy.io.savemat(p, {"t": s["t"][:, None], "V": s["V"][None, :], "I": s["I"],
                         "kp": 160.18, "kv": np.array([[243.45]]), "n_pole": np.int16(4),
                         "label": "rig 7", "info": {"operator": "A", "gain": 2.0},
                         "notes": np.array([["a"], [1.0]], dtype=object),
                         "empty": np.zeros((0, 0))})
    df = _read_quiet(p)
    assert sorted(df.columns) == ["I", "V", "t"]
    np.testing.assert_array_equal(df["V"], s["V"])  # 1xN and Nx1 alike
    np.testing.assert_array_equal(df["t"], s["t"])
    assert df.attrs["constants"] == {"kp": 160.18, "kv": 243.45, "n_pole": 4.0}
    assert df.attrs["source"] == str(p)
    assert validate_record(df, ("V", "I")).dt == pytest.approx(DT)


def test_mat_v5_other_lengths_and_matrices_are_named_in_a_warning(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig.mat"
    scipy.io.savemat(p, {**s, "ref": np.ones(50), "M": np.ones((3, 2)),
                         "z": s["V"] * 1j, "flag": s["V"] > 0})
    with pytest.warns(DataWarning, match=r"rig\.mat: variable\(s\) .*'M' \(3x2 matrix.*"
                                         r"'ref' \(50 samples, the record has 200\)"):
        df = read_record(p)
    assert sorted(df.columns) == ["I", "V", "flag", "t"]  # logical read as 0/1
    assert set(df["flag"]) == {0, 1}
    with pytest.warns(DataWarning), \
            pytest.raises(DataError, match=r"names \['ref'\] not in the file.*'ref' was left "
                                           r"out: 50 samples, the record has 200"):
        read_record(p, {"V": "ref"})


def test_mat_column_mapping(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig.mat"
    scipy.io.savemat(p, {"time": s["t"], "vir": s["V"], "cur": s["I"], "t": 7.0})
    df = _read_quiet(p, parse_column_map("t=time,V=vir,I=cur"))
    assert sorted(df.columns) == ["I", "V", "t"]
    np.testing.assert_array_equal(df["V"], s["V"])
    assert df.attrs["constants"] == {"t": 7.0}


def test_mat_without_vector_is_refused_naming_the_file(tmp_path: Path) -> None:
    p = tmp_path / "params.mat"
    scipy.io.savemat(p, {"kp": 1.0, "name": "rig"})
    with pytest.raises(DataError, match=r"params\.mat: no numeric vector in the file.*"
                                        r"'name' \(not numeric\)"):
        read_record(p)


@pytest.mark.parametrize("content", [b"", b"not a mat file at all" * 20,
                                     b"MATLAB 5.0 MAT-file" + bytes(200)])
def test_corrupt_mat_is_one_data_error(tmp_path: Path, content: bytes) -> None:
    p = tmp_path / "bad.mat"
    p.write_bytes(content)
    with pytest.raises(DataError, match=r"bad\.mat: ") as err:
        read_record(p)
    assert "\n" not in str(err.value)


@pytest.mark.skipif(not EMPS.exists(), reason="EMPS data set not in shared/external")
def test_emps_data_set() -> None:
    start = time.perf_counter()
    df = _read_quiet(EMPS)
    elapsed = time.perf_counter() - start
    assert sorted(df.columns) == ["qg", "qm", "t", "vir"]
    assert len(df) == 24841 and (df.dtypes == np.float64).all()
    assert df.attrs["constants"] == pytest.approx({"gtau": 35.15065188, "kp": 160.18,
                                                   "kv": 243.45})
    assert validate_record(df, ("qm", "vir")).dt == pytest.approx(1e-3, rel=1e-4)
    mapped = _read_quiet(EMPS, parse_column_map("V=vir,y=qm"))
    assert {"t", "V", "y"} <= set(mapped.columns)
    assert elapsed < 2.0


# --------------------------------------------------------------------------- MATLAB v7.3

_CLASSES = {"float64": "double", "float32": "single", "int16": "int16", "bool": "logical",
            "uint8": "uint8"}


def _write_mat73(path: Path, variables: dict[str, Any]) -> None:
    """An HDF5 file laid out as MATLAB writes ``save -v7.3``: a 512-byte header,
    every array stored transposed, its class in ``MATLAB_class``."""
    with h5py.File(path, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        for name, value in variables.items():
            if isinstance(value, str):  # char row vector: uint16 code points
                ds = f.create_dataset(name, data=np.array([[ord(c)] for c in value],
                                                          dtype=np.uint16))
                ds.attrs["MATLAB_class"] = np.bytes_("char")
            elif isinstance(value, dict):  # struct: a group of fields
                g = f.create_group(name)
                g.attrs["MATLAB_class"] = np.bytes_("struct")
                for key, field in value.items():
                    g.create_dataset(key, data=np.atleast_2d(field).T)
            elif isinstance(value, list):  # cell: references into #refs#
                ds = f.create_dataset(name, (len(value), 1), dtype=h5py.ref_dtype)
                for k, item in enumerate(value):
                    ds[k, 0] = refs.create_dataset(f"{name}{k}", data=np.atleast_2d(item)).ref
                ds.attrs["MATLAB_class"] = np.bytes_("cell")
            elif value is None:  # [] : MATLAB stores its size and a flag
                ds = f.create_dataset(name, data=np.array([0, 0], dtype=np.uint64))
                ds.attrs["MATLAB_class"] = np.bytes_("double")
                ds.attrs["MATLAB_empty"] = np.uint8(1)
            else:
                arr = np.atleast_2d(np.asarray(value))  # rows x columns, as MATLAB sees it
                ds = f.create_dataset(name, data=arr.T.astype(np.uint8) if arr.dtype == bool
                                      else arr.T)
                ds.attrs["MATLAB_class"] = np.bytes_(_CLASSES[str(arr.dtype)])
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 10:00:00 2026 " \
             b"HDF5 schema 1.00 ."
    with path.open("r+b") as fh:
        fh.write(header.ljust(116, b" ") + bytes(8) + b"\x00\x02IM")


def test_mat_v73_is_read_transposed_back(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig73.mat"
    _write_mat73(p, {"t": s["t"][:, None], "vir": s["V"][None, :],
                     "cur": s["I"].astype(np.float32)[:, None], "kp": 160.18,
                     "poles": np.int16(4), "ok": (s["V"] > 0)[:, None],
                     "name": "EMPS", "cfg": {"gain": 2.0}, "c": [1.0, 2.0], "none": None,
                     "M": np.arange(6.0).reshape(3, 2), "short": np.ones((1, 7))})
    assert p.read_bytes()[512:520] == b"\x89HDF\r\n\x1a\n"  # header first, as MATLAB does
    with pytest.warns(DataWarning, match=r"'M' \(3x2 matrix, not a vector\), "
                                         r"'short' \(7 samples, the record has 200\)"):
        df = read_record(p, {"V": "vir", "I": "cur"})
    assert sorted(df.columns) == ["I", "V", "ok", "t"]
    np.testing.assert_array_equal(df["V"], s["V"])
    np.testing.assert_allclose(df["I"], s["I"], rtol=1e-6)
    assert df.attrs["constants"] == {"kp": 160.18, "poles": 4.0}
    assert validate_record(df, ("V", "I")).dt == pytest.approx(DT)


def test_mat_v73_values_of_a_saved_v5_twin_match(tmp_path: Path) -> None:
    s = _signals()
    v5, v73 = tmp_path / "a.mat", tmp_path / "b.mat"
    scipy.io.savemat(v5, {"t": s["t"][:, None], "V": s["V"][:, None], "kp": 2.0})
    _write_mat73(v73, {"t": s["t"][:, None], "V": s["V"][:, None], "kp": 2.0})
    a, b = _read_quiet(v5), _read_quiet(v73)
    pd.testing.assert_frame_equal(a.sort_index(axis=1), b.sort_index(axis=1))
    assert a.attrs["constants"] == b.attrs["constants"]


def test_corrupt_mat_v73_is_one_data_error(tmp_path: Path) -> None:
    p = tmp_path / "bad73.mat"
    p.write_bytes(b"MATLAB 7.3 MAT-file".ljust(512, b" ") + b"\x89HDF\r\n\x1a\n" + bytes(100))
    with pytest.raises(DataError, match=r"bad73\.mat: cannot read as a MATLAB file") as err:
        read_record(p)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- TDMS

WF = {"wf_increment": DT, "wf_start_offset": 0.5,
      "wf_start_time": np.datetime64("2026-11-23T10:00:00")}


def _write_tdms(path: Path, channels: list[ChannelObject]) -> None:
    with TdmsWriter(path) as writer:
        writer.write_segment(channels)


def test_tdms_channels_and_the_waveform_time_base(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig.tdms"
    _write_tdms(p, [ChannelObject("rig", "V", s["V"], WF), ChannelObject("rig", "I", s["I"], WF),
                    ChannelObject("rig", "note", ["x"] * N)])
    df = _read_quiet(p)
    assert list(df.columns) == ["t", "V", "I"]
    np.testing.assert_allclose(df["t"], 0.5 + s["t"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(df["V"], s["V"])
    assert df.attrs["start_time"] == "2026-11-23T10:00:00"
    assert validate_record(df, ("V", "I")).dt == pytest.approx(DT)


def test_tdms_same_channel_in_two_groups_is_prefixed(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig.tdms"
    _write_tdms(p, [ChannelObject("motor", "V", s["V"], WF), ChannelObject("brake", "V", s["I"], WF),
                    ChannelObject("motor", "speed", s["I"], WF)])
    df = _read_quiet(p, parse_column_map("V=motor/V,omega=speed"))
    assert sorted(df.columns) == ["V", "brake/V", "omega", "t"]
    np.testing.assert_array_equal(df["V"], s["V"])


def test_tdms_time_channel_is_used_not_built(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rig.tdms"
    _write_tdms(p, [ChannelObject("rig", "time", s["t"] + 3.0), ChannelObject("rig", "V", s["V"], WF)])
    df = _read_quiet(p, {"t": "time"})
    assert list(df.columns) == ["t", "V"]
    assert df["t"].iloc[0] == pytest.approx(3.0)
    q = tmp_path / "t.tdms"
    _write_tdms(q, [ChannelObject("rig", "t", s["t"]), ChannelObject("rig", "V", s["V"], WF)])
    assert list(_read_quiet(q).columns) == ["t", "V"]


def test_tdms_time_stamp_channel_becomes_seconds(tmp_path: Path) -> None:
    s = _signals()
    stamps = np.datetime64("2026-11-23T10:00:00") + (s["t"] * 1e6).round().astype("timedelta64[us]")
    p = tmp_path / "rig.tdms"
    _write_tdms(p, [ChannelObject("rig", "stamp", stamps), ChannelObject("rig", "V", s["V"], WF)])
    df = _read_quiet(p)
    assert list(df.columns) == ["t", "V"]
    np.testing.assert_allclose(df["t"], s["t"], atol=1e-9)
    assert df.attrs["start_time"] == "2026-11-23T10:00:00"


def test_tdms_problems(tmp_path: Path) -> None:
    s = _signals()
    p = tmp_path / "rates.tdms"
    _write_tdms(p, [ChannelObject("rig", "V", s["V"], WF),
                    ChannelObject("rig", "I", s["I"], {**WF, "wf_increment": 2 * DT})])
    with pytest.raises(DataError, match=r"rates\.tdms: channels 'V' .* and 'I' .* different rates"):
        read_record(p)
    p = tmp_path / "short.tdms"
    _write_tdms(p, [ChannelObject("rig", "V", s["V"], WF), ChannelObject("rig", "I", s["I"], WF),
                    ChannelObject("slow", "temp", np.ones(10), WF)])
    with pytest.warns(DataWarning, match=r"channel\(s\) 'temp' \(10 samples, the record has 200\)"):
        assert list(read_record(p).columns) == ["t", "V", "I"]
    p = tmp_path / "nowave.tdms"
    _write_tdms(p, [ChannelObject("rig", "V", s["V"])])
    with pytest.raises(DataError, match=r"nowave\.tdms: missing column\(s\) 't'"):
        validate_record(_read_quiet(p), ("V",))
    p = tmp_path / "text.tdms"
    _write_tdms(p, [ChannelObject("rig", "note", ["a", "b"])])
    with pytest.raises(DataError, match=r"text\.tdms: no numeric vector"):
        read_record(p)
    p = tmp_path / "bad.tdms"
    p.write_bytes(b"TDSm" + bytes(40))
    with pytest.raises(DataError, match=r"bad\.tdms: cannot read as a TDMS file") as err:
        read_record(p)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- delimited text

DIALECTS = [(",", ".", "csv"), (";", ",", "csv"), (";", ".", "csv"), ("\t", ".", "tsv"),
            ("\t", ",", "txt"), ("\t", ".", "txt"), (";", ",", "txt")]


@pytest.mark.parametrize(("sep", "decimal", "ext"), DIALECTS)
def test_every_dialect_reads_the_same_numbers(tmp_path: Path, noisy_record: pd.DataFrame,
                                              sep: str, decimal: str, ext: str) -> None:
    p = tmp_path / f"rec.{ext}"
    noisy_record.to_csv(p, sep=sep, decimal=decimal, index=False)
    df = _read_quiet(p)
    assert list(df.columns) == list(noisy_record.columns)
    np.testing.assert_allclose(df.to_numpy(), noisy_record.to_numpy(), rtol=1e-15)
    assert validate_record(df, ("V", "I", "omega")).dt == pytest.approx(1e-3)


def test_comment_lines_above_the_header_are_skipped_and_lines_still_counted(
        tmp_path: Path, noisy_record: pd.DataFrame) -> None:
    """A logger's "# rig 7, operator jo" lines above the header were read as the
    header ("cannot tell the separator")."""
    plain = tmp_path / "plain.csv"
    noisy_record.to_csv(plain, index=False)
    noted = tmp_path / "noted.csv"
    noted.write_text("# rig 7, operator jo\n  # date 2026-03-01; 1 kHz\n" + plain.read_text())
    a, b = _read_quiet(plain), _read_quiet(noted)
    pd.testing.assert_frame_equal(a, b, check_like=False, check_flags=False)
    broken = noisy_record.copy()
    broken.loc[50, "I"] = np.nan
    broken.to_csv(plain, index=False)
    noted.write_text("sep=,\n# rig 7\n" + plain.read_text())
    with pytest.raises(DataError, match=r"first at row 50 \(from 0; line 54 of the file, its "
                                        r"header on line 3\)"):
        validate_record(_read_quiet(noted), ("V", "I"))
    assert noted.read_text().splitlines()[53].split(",")[2] == ""


def test_a_separator_ending_every_line_adds_no_column(tmp_path: Path) -> None:
    """A spreadsheet's export with "," at the end of each line: the empty
    column 'Unnamed: 3' was listed among the record's columns."""
    p = tmp_path / "trail.csv"
    p.write_text("t,V,I,\n0.0,1.5,0.1,\n0.001,2.5,0.2,\n")
    assert list(_read_quiet(p).columns) == ["t", "V", "I"]
    kept = tmp_path / "kept.csv"
    kept.write_text("t,V,I,\n0.0,1.5,0.1,7\n0.001,2.5,0.2,\n")  # a value: kept, named
    assert list(_read_quiet(kept).columns) == ["t", "V", "I", "Unnamed: 3"]


def test_european_csv(tmp_path: Path) -> None:
    p = tmp_path / "eu.csv"
    p.write_text("t;V;I\n0,000;1,25;-3,5\n0,001;1,5e-3;3\n0,002;2;4,0\n")
    df = _read_quiet(p)
    assert df.to_dict("list") == {"t": [0.0, 0.001, 0.002], "V": [1.25, 0.0015, 2.0],
                                  "I": [-3.5, 3.0, 4.0]}


def test_decimal_mark_first_seen_late_is_still_read(tmp_path: Path) -> None:
    rows = [f"{k};{k % 3}" for k in range(80)] + ["80;0,5", "81;1,5"]
    p = tmp_path / "late.csv"
    p.write_text("t;V\n" + "\n".join(rows) + "\n")
    df = _read_quiet(p)
    assert df["V"].iloc[-1] == 1.5 and df["V"].dtype == np.float64


@pytest.mark.parametrize(("text", "expected"), [
    ("t,V\n0,1\n1,2\n", (",", ".")),          # integers: the header's separator decides
    ("V\n1,5\n2,5\n", (";", ",")),            # one column, decimal comma
    ("t;V\n0;1\n1;2\n", (";", ",")),           # semicolons, no decimal seen: European
    ("t\tV\n0.5\t1\n", ("\t", ".")),
])
def test_sniffing_prefers_all_numeric_columns(text: str, expected: tuple[str, str]) -> None:
    d = sniff_dialect(text, "x.csv")
    assert (d.sep, d.decimal) == expected


@pytest.mark.parametrize(("text", "message"), [
    ("0.0,1.0\n0.1,2.0\n", "the first line holds numbers, not column names"),
    ("t,V\n0.0,1.0,3\n0.1,2.0\n", "cannot tell the separator: with commas line 2 has 3 fields"),
    ("\n\n", "the file is empty"),
])
def test_delimited_problems(tmp_path: Path, text: str, message: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(DataError, match=rf"bad\.csv: {message}"):
        read_record(p)


def test_header_spaces_and_latin1(tmp_path: Path) -> None:
    p = tmp_path / "old.csv"
    p.write_bytes("t; U [µV]; I\n0,0; 1,5; 2\n0,1; 2,5; 3\n".encode("latin-1"))
    df = _read_quiet(p, {"V": "U [µV]"})
    assert list(df.columns) == ["t", "V", "I"] and df["V"].tolist() == [1.5, 2.5]


def test_ragged_row_beyond_the_sniffed_lines_is_one_data_error(tmp_path: Path) -> None:
    p = tmp_path / "ragged.csv"
    p.write_text("t,V\n" + "".join(f"{k},{k}\n" for k in range(100)) + "1,2,3,4\n")
    with pytest.raises(DataError, match=r"ragged\.csv: cannot read as a CSV file: .*") as err:
        read_record(p)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- date-time time

def _stamps(n: int = 5, fmt: str = "%Y-%m-%d %H:%M:%S.%f") -> list[str]:
    base = pd.Timestamp("2026-11-23 10:00:00")
    return [(base + pd.Timedelta(milliseconds=k)).strftime(fmt)[:-3] for k in range(n)]


def test_datetime_time_column_becomes_seconds(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    p.write_text("time,V\n" + "".join(f"{s},{k}.5\n" for k, s in enumerate(_stamps())))
    df = _read_quiet(p, {"t": "time"})
    np.testing.assert_allclose(df["t"], [0.0, 0.001, 0.002, 0.003, 0.004], atol=1e-12)
    assert df.attrs["start_time"] == "2026-11-23T10:00:00"
    # the one date-time column is the time base even unmapped
    df = _read_quiet(p)
    assert list(df.columns) == ["t", "V"] and df["t"].iloc[1] == pytest.approx(0.001)


@pytest.mark.parametrize("fmt", ["%d.%m.%Y %H:%M:%S.%f", "%Y-%m-%dT%H:%M:%S.%f"])
def test_european_datetimes_with_decimal_comma(tmp_path: Path, fmt: str) -> None:
    p = tmp_path / "log.csv"
    rows = [f"{s.replace('.', ',') if fmt.startswith('%Y') else s[:-4] + ',' + s[-3:]};{k},25"
            for k, s in enumerate(_stamps(fmt=fmt))]
    p.write_text("Zeit;V\n" + "\n".join(rows) + "\n")
    df = _read_quiet(p)
    np.testing.assert_allclose(df["t"], np.arange(5) * 1e-3, atol=1e-12)
    assert df["V"].tolist() == [0.25, 1.25, 2.25, 3.25, 4.25]
    assert df.attrs["start_time"] == "2026-11-23T10:00:00"


def test_ambiguous_day_month_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "us.csv"
    p.write_text("t,V\n01/02/2026 10:00,1\n02/02/2026 10:00,2\n")
    with pytest.raises(DataError, match=r"us\.csv: column 't': the order of day and month"):
        read_record(p)


def test_parquet_datetime_time_column(tmp_path: Path) -> None:
    s = _signals()
    stamps = pd.Timestamp("2026-11-23 10:00:00") + pd.to_timedelta(s["t"], unit="s")
    p = tmp_path / "rec.parquet"
    pd.DataFrame({"t": stamps, "V": s["V"], "I": s["I"]}).to_parquet(p, index=False)
    df = _read_quiet(p)
    np.testing.assert_allclose(df["t"], s["t"], atol=1e-9)
    assert validate_record(df, ("V", "I")).dt == pytest.approx(DT)



def test_repeated_column_names_are_refused_naming_the_column(tmp_path: Path) -> None:
    """A Parquet file's repeated name gave Arrow's message about its internal
    fields; a DataFrame's gave a raw AttributeError. A column named once is
    still taken beside a repeated one the model does not read."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    s = _signals()
    table = pa.table([s["t"], s["V"], s["I"], s["I"]], names=["t", "V", "I", "I"])
    p = tmp_path / "twice.parquet"
    pq.write_table(table, p)
    with pytest.raises(DataError, match=r"twice\.parquet: the file has 2 columns named 'I'; "
                                        r"rename one"):
        read_record(p)
    frame = pd.DataFrame(np.column_stack([s["t"], s["V"], s["I"], s["V"]]),
                         columns=["t", "V", "I", "V"])
    with pytest.raises(DataError, match=r"^rig: the frame has 2 columns named 'V'; rename"):
        validate_record(frame, ("V", "I"), source="rig")
    frame.columns = ["t", "V", "I", "x"]
    frame = pd.concat([frame, frame[["x"]]], axis=1)
    assert validate_record(frame, ("V", "I")).dt == pytest.approx(DT)


# --------------------------------------------------------------------------- time base

def test_a_float32_time_column_is_judged_at_its_own_resolution(tmp_path: Path) -> None:
    """A 25 s record at 1 kHz saved as float32 Parquet: float32 holds 16 s to
    1.9 µs, 0.19 % of the interval, and the record was refused as jittery."""
    n = 25_000
    t = np.arange(n) * 1e-3
    rng = np.random.default_rng(3)
    frame = pd.DataFrame({"t": t, "V": rng.standard_normal(n), "I": rng.standard_normal(n)})
    p = tmp_path / "f32.parquet"
    frame.astype(np.float32).to_parquet(p, index=False)
    df = read_record(p)
    assert df["t"].dtype == np.float32
    assert validate_record(df, ("V", "I")).dt == pytest.approx(1e-3, rel=1e-6)
    jittered = t.copy()
    jittered[20_001:] += 5e-6    # one interval 0.5 % long: beyond 0.1 % + 0.19 %
    frame.assign(t=jittered).astype(np.float32).to_parquet(p, index=False)
    with pytest.raises(DataError, match=r"jitter 0\.\d+ % \(tolerance 0\.1 %, plus the values' "
                                        r"own resolution 1\.91e-06 s\), .* at row 20001"):
        validate_record(read_record(p), ("V", "I"))
    with pytest.raises(DataError, match=r"jitter .* \(tolerance 0\.1 %\)"):
        validate_record(frame.assign(t=jittered), ("V", "I"))  # float64: no resolution


def test_check_time_base_reports_jitter_and_row() -> None:
    t = np.arange(100) * DT
    assert check_time_base(t, "rig.csv") == pytest.approx(DT)
    t[60:] += 0.5 * DT
    with pytest.raises(DataError, match=r"rig\.csv: column 't' is not uniformly sampled: "
                                        r"jitter 50 % \(tolerance 0\.1 %\), interval 0\.0015 s "
                                        r"at row 60"):
        check_time_base(t, "rig.csv")
    assert check_time_base(t[:60], "rig.csv") == pytest.approx(DT)
    assert check_time_base(t, "rig.csv", tolerance=0.6) == pytest.approx(DT)
    with pytest.raises(DataError, match="not increasing at row 3"):
        check_time_base([0.0, 1.0, 2.0, 2.0], "x")
    with pytest.raises(DataError, match="needs at least 2"):
        check_time_base([0.0], "x")
    with pytest.raises(DataError, match="1 NaN/inf value"):
        check_time_base([0.0, np.nan, 2.0], "x")


def test_validate_record_uses_the_time_base_check(noisy_record: pd.DataFrame) -> None:
    df = noisy_record.copy()
    df.loc[2000:, "t"] += 0.0005
    with pytest.raises(DataError, match=r"not uniformly sampled: jitter 50 % .* at row 2000"):
        validate_record(df, ("V",), source="bench.csv")


# --------------------------------------------------------------------------- every format

def test_unknown_suffix_lists_every_readable_one(tmp_path: Path) -> None:
    p = tmp_path / "rec.xlsx"
    p.write_text("x")
    with pytest.raises(DataError, match=r"unknown file type '\.xlsx'; allowed: \.csv, \.parquet, "
                                        r"\.pq, \.txt, \.tsv, \.mat, \.tdms"):
        read_record(p)


def test_mapping_problems(tmp_path: Path) -> None:
    p = tmp_path / "rec.csv"
    p.write_text("t,V,volts\n0,1,2\n1,2,3\n")
    with pytest.raises(DataError, match=r"gives the file's column 'volts' to 'V' and 'I'"):
        read_record(p, {"V": "volts", "I": "volts"})
    df = _read_quiet(p, {"V": "volts"})  # the mapped column replaces the file's own V
    assert list(df.columns) == ["t", "V"] and df["V"].tolist() == [2, 3]
    d = tmp_path / "dir.csv"
    d.mkdir()
    with pytest.raises(DataError, match=r"dir\.csv: not a file"):
        read_record(d)


def test_corrupt_parquet_is_one_data_error(tmp_path: Path) -> None:
    p = tmp_path / "bad.parquet"
    p.write_bytes(b"PAR1" + bytes(64))
    with pytest.raises(DataError, match=r"bad\.parquet: cannot read as a Parquet file") as err:
        read_record(p)
    assert "\n" not in str(err.value)


@settings(deadline=None, max_examples=120, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(content=st.one_of(st.binary(max_size=600),
                         st.text(alphabet="0123456789,;.\t\n -:tVIe", max_size=300)
                         .map(str.encode)),
       suffix=st.sampled_from(READABLE_SUFFIXES))
def test_any_bytes_give_a_frame_or_one_data_error(tmp_path: Path, content: bytes,
                                                  suffix: str) -> None:
    p = tmp_path / f"fuzz{suffix}"
    p.write_bytes(content)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CondmonWarning)  # any other warning fails
            df = read_record(p)
    except DataError as err:
        assert str(err).startswith(str(p)) and "\n" not in str(err)
    else:
        assert isinstance(df, pd.DataFrame) and df.attrs["source"] == str(p)


def test_truncated_tdms_warns_once_instead_of_logging(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    s = _signals()
    p = tmp_path / "cut.tdms"
    _write_tdms(p, [ChannelObject("rig", "V", s["V"], WF)])
    p.write_bytes(p.read_bytes()[:-101])
    with pytest.warns(DataWarning, match=r"cut\.tdms: .*less data than expected.* \(npTDMS"):
        df = read_record(p)
    assert 0 < len(df) < N
    assert "nptdms" not in capsys.readouterr().err


def test_every_format_gives_the_same_estimate(tmp_path: Path, noisy_record: pd.DataFrame) -> None:
    from condmon.identify import estimate

    cols = {c: noisy_record[c].to_numpy() for c in noisy_record.columns}
    files = {"eu.csv": lambda p: noisy_record.to_csv(p, sep=";", decimal=",", index=False),
             "rec.tsv": lambda p: noisy_record.to_csv(p, sep="\t", index=False),
             "v5.mat": lambda p: scipy.io.savemat(p, {**{k: v[:, None] for k, v in cols.items()},
                                                      "kp": 1.0}),
             "v73.mat": lambda p: _write_mat73(p, {k: v[:, None] for k, v in cols.items()}),
             "rec.tdms": lambda p: _write_tdms(p, [ChannelObject("rig", k, v)
                                                   for k, v in cols.items()])}
    reference = estimate(noisy_record).parameters
    for name, write in files.items():
        p = tmp_path / name
        write(p)
        res = estimate(_read_quiet(p))
        assert res.accepted, name
        assert res.parameters == pytest.approx(reference, rel=1e-9), name


def test_space_separated_text_is_refused_clearly(tmp_path: Path) -> None:
    p = tmp_path / "spaces.txt"
    p.write_text("t V I\n0.0 1.0 2.0\n0.1 1.5 2.5\n")
    with pytest.raises(DataError, match=r"spaces\.txt: cannot tell the separator: no comma, "
                                        r"semicolon or tab splits"):
        read_record(p)


def test_text_column_does_not_prevent_reading(tmp_path: Path) -> None:
    p = tmp_path / "notes.csv"
    p.write_text("t;V;note\n0,0;1,5;start\n0,1;2,5;x\n")
    df = _read_quiet(p)
    assert df["V"].tolist() == [1.5, 2.5] and df["note"].tolist() == ["start", "x"]


def test_quoted_decimal_commas_in_a_comma_csv(tmp_path: Path) -> None:
    p = tmp_path / "quoted.csv"
    p.write_text('"t","V"\n"0,000","1,5"\n"0,001","2,5"\n')
    assert _read_quiet(p).to_dict("list") == {"t": [0.0, 0.001], "V": [1.5, 2.5]}


def test_a_file_column_given_to_two_model_columns_names_both(tmp_path: Path) -> None:
    """`--columns x=position` where `position` is read as itself said "names
    'position' for more than one column", naming neither taker."""
    p = tmp_path / "r.csv"
    pd.DataFrame({"t": [0.0, 1.0], "position": [1.0, 2.0]}).to_csv(p, index=False)
    with pytest.raises(DataError, match="gives the file's column 'position' to 'x' and "
                       "'position'; a file column reads as one model column"):
        read_record(p, {"x": "position", "position": "position"})


def test_excel_s_sep_line_is_understood(tmp_path: Path) -> None:
    """Excel's `sep=;` first line was taken for the header and refused with a
    misleading reason."""
    p = tmp_path / "excel.csv"
    p.write_text("sep=;\nt;V\n0,000;1,5\n0,001;2,5\n", encoding="utf-8-sig")
    frame = read_record(p)
    assert frame["t"].tolist() == [0.0, 0.001] and frame["V"].tolist() == [1.5, 2.5]
    p.write_text("sep=,\nt;V\n0,000;1,5\n0,001;2,5\n")
    with pytest.raises(DataError, match="line 1 says sep=,, but the lines after it read as "
                       "semicolon-separated, decimal comma"):
        read_record(p)


def test_an_excel_error_cell_is_a_missing_value_at_its_own_row(tmp_path: Path) -> None:
    """A German Excel `#NV` cell made the column "not numeric (row 0: '1,5')",
    quoting a valid value of another row."""
    p = tmp_path / "excel.csv"
    p.write_text("t;V\n0,000;1,5\n0,001;#NV\n0,002;2,5\n")
    frame = read_record(p)
    assert frame["V"].tolist()[0] == 1.5 and np.isnan(frame["V"].tolist()[1])


def test_a_scaled_column_names_its_real_bad_row_and_never_a_python_repr() -> None:
    """An empty cell before a text cell in a scaled column was reported as
    'not numeric (row 49: nan)': the empty cell's row and numpy's repr."""
    import pandas as pd

    from condmon.io.rig import RecordSettings, apply_record_settings

    values: list[object] = [float(i) for i in range(80)]
    values[49] = None          # an empty cell: missing, named later at its own row
    values[59] = "x1"          # text: not a number
    df = pd.DataFrame({"t": np.arange(80) * 1e-3, "p": values})
    settings = RecordSettings(scale={"p": 2.0})
    with pytest.raises(DataError) as err:
        apply_record_settings(df, settings, "rig.txt")
    assert "column 'p' is not numeric (row 59: 'x1')" in str(err.value)
    assert "nan" not in str(err.value).lower() and "np." not in str(err.value)
    df.loc[59, "p"] = 59.0
    out = apply_record_settings(df, settings, "rig.txt")
    assert np.isnan(out["p"].iloc[49]) and out["p"].iloc[59] == 118.0


def test_a_remapped_t_takes_its_new_column_s_own_scale() -> None:
    """The stand's declaration reads t from a sample counter at 250 Hz; mapped
    to a column of seconds on the command line, t was silently still divided
    by 250."""
    from condmon.workflows.records import EstimateOptions

    model = str(Path(__file__).resolve().parents[1] / "examples" / "hydraulic-actuator"
                / "rotary-actuator.toml")
    assert EstimateOptions(model=model).settings().sample_rate == 250.0
    moved = EstimateOptions(model=model, columns={"t": "secs", "pA": "pa_si"}).settings()
    assert moved.sample_rate is None and moved.columns["t"] == "secs"
    assert "pA" not in moved.scale and "pA" not in moved.accuracy
    assert moved.scale.get("pB") == EstimateOptions(model=model).settings().scale["pB"]


def test_columns_naming_a_state_says_so_and_names_its_sensor(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--columns x=...` for a state said 'for more than one column'."""
    from condmon.cli.main import main

    template = Path(__file__).resolve().parents[1] / "examples" / "template.toml"
    rec = tmp_path / "r.csv"
    assert main(["simulate", "plant", str(template), "--out", str(rec), "--duration",
                 "3"]) == 0
    capsys.readouterr()
    assert main(["estimate", str(rec), "--model", str(template), "--columns", "x=pos"]) == 2
    err = capsys.readouterr().err
    assert "'x' is a state of model 'my-machine', not a record column" in err
    assert "write pos=pos" in err and len(err.strip().splitlines()) == 1


def test_the_readme_column_map_of_a_sensor_named_like_its_state_is_taken(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """README's `--columns V=volts,I=amps,omega=speed`: the DC motor's sensors
    I and omega share their states' names, and the map was refused as naming
    a state, with a hint to write what had been written."""
    from condmon.cli.main import main

    rec = tmp_path / "healthy.csv"
    assert main(["simulate", "actuator", "--out", str(rec), "--seed", "1"]) == 0
    frame = pd.read_csv(rec).rename(columns={"V": "volts", "I": "amps", "omega": "speed"})
    renamed = tmp_path / "rig.csv"
    frame.to_csv(renamed, index=False)
    capsys.readouterr()
    assert main(["estimate", str(renamed), "--columns", "V=volts,I=amps,omega=speed",
                 "--json"]) == 0
    mapped = json.loads(capsys.readouterr().out)
    assert main(["estimate", str(rec), "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert mapped["parameters"] == plain["parameters"]
