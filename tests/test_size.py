"""A small file must not take the machine: record sizes are told before loading.

The default run uses small files with a lowered limit (``CONDMON_MAX_SAMPLES``);
the slow study builds the real bombs (a 4.5 MB Parquet file of 250 M rows, a
2 GB sparse CSV, a 950 MB CSV of 50 M rows, sparse and compressed .mat files)
and measures the peak memory of ``condmon estimate`` on each (<= 1 GB).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from condmon.errors import DataError
from condmon.io import read_record
from condmon.io.size import record_limits, record_samples


@pytest.fixture()
def small_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONDMON_MAX_SAMPLES", "1000")
    monkeypatch.setenv("CONDMON_MAX_RECORD_BYTES", "50000")


def _frame(n: int) -> pd.DataFrame:
    return pd.DataFrame({"t": np.arange(n) * 1e-3, "V": np.zeros(n), "I": np.zeros(n)})


@pytest.mark.parametrize("suffix", [".parquet", ".csv", ".txt", ".mat", ".tdms"])
def test_a_record_beyond_the_limit_is_refused_before_loading(
        tmp_path: Path, small_limit: None, suffix: str) -> None:
    path = tmp_path / f"r{suffix}"
    df = _frame(500)  # 1,500 values > 1,000
    if suffix == ".parquet":
        df.to_parquet(path)
    elif suffix == ".csv":
        df.to_csv(path, index=False)
    elif suffix == ".txt":
        df.to_csv(path, sep="\t", index=False)
    elif suffix == ".mat":
        import scipy.io

        scipy.io.savemat(path, {c: df[c].to_numpy()[:, None] for c in df.columns})
    else:
        from nptdms import ChannelObject, TdmsWriter

        with TdmsWriter(path) as w:
            w.write_segment([ChannelObject("rig", c, df[c].to_numpy()) for c in df.columns])
    assert record_samples(path, suffix) == 1500 or suffix in (".csv", ".txt")
    with pytest.raises(DataError, match=r"values, beyond the limit of 1,000 values .*"
                                        r"CONDMON_MAX_SAMPLES.*nothing was loaded"):
        read_record(path)


def test_a_record_within_the_limit_is_read(tmp_path: Path, small_limit: None) -> None:
    path = tmp_path / "r.parquet"
    _frame(300).to_parquet(path)
    assert len(read_record(path)) == 300
    assert record_limits().max_samples == 1000


def test_a_large_text_file_is_refused_by_its_size(tmp_path: Path, small_limit: None) -> None:
    path = tmp_path / "sparse.csv"
    with path.open("wb") as fh:
        fh.truncate(60_000)  # all zero bytes, no line
    with pytest.raises(DataError, match=r"0 MB of text, beyond the limit of 0 MB"):
        read_record(path)


def test_a_sparse_matrix_in_a_mat_file_counts_its_shape(tmp_path: Path) -> None:
    import scipy.io
    import scipy.sparse

    m = scipy.sparse.csc_matrix((np.ones(2), (np.array([0, 9]), np.array([0, 99_999]))),
                                shape=(200_000, 100_000))
    path = tmp_path / "sparse.mat"
    scipy.io.savemat(path, {"t": np.arange(5.0)[:, None], "big": m})
    with pytest.raises(DataError, match="20,000,000,005 values, beyond the limit"):
        read_record(path)


# --- the real bombs: peak memory of the command line --------------------------------------

def _peak_kb(args: list[str]) -> tuple[int, int, str]:
    """Exit status, peak resident memory [KB] (VmHWM: since the process's own
    exec, unlike ru_maxrss) and stderr of ``condmon ARGS`` in a fresh process."""
    code = ("import re, sys\nfrom condmon.cli.main import main\n"
            f"rc = main({args!r})\n"
            "hwm = re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read())\n"
            "print(hwm.group(1), file=sys.stderr)\n"
            "sys.exit(rc)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    lines = proc.stderr.strip().splitlines()
    return proc.returncode, int(lines[-1]), "\n".join(lines[:-1])


@pytest.mark.slow
def test_the_bombs_are_refused_within_a_gigabyte(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq
    import scipy.io

    files = {}
    schema = pa.schema([(c, pa.float64()) for c in ("t", "V", "I", "omega")])
    zeros = pa.array(np.zeros(10_000_000))
    files["parquet bomb"] = tmp_path / "bomb.parquet"
    with pq.ParquetWriter(files["parquet bomb"], schema, compression="zstd") as w:
        for _ in range(25):
            w.write_table(pa.table([zeros] * 4, schema=schema))
    files["sparse csv"] = tmp_path / "sparse.csv"
    with files["sparse csv"].open("wb") as fh:
        fh.truncate(2 * 1024 ** 3)
    files["50 M-row csv"] = tmp_path / "big.csv"
    with files["50 M-row csv"].open("w") as fh:
        fh.write("t,V,I,omega\n")
        block = "0.001,1.0,0.5,10.0\n" * 100_000
        for _ in range(500):
            fh.write(block)
    files["compressed mat"] = tmp_path / "zeros.mat"
    scipy.io.savemat(files["compressed mat"], {"t": np.zeros((150_000_000, 1))},
                     do_compression=True)
    for name, path in files.items():
        rc, kb, err = _peak_kb(["estimate", str(path)])
        assert rc == 2 and "beyond the limit" in err and len(err.splitlines()) == 1, name
        assert kb < 1024 * 1024, f"{name}: {kb / 1024:.0f} MB"
