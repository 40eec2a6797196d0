"""MATLAB ``.mat`` records: v4/v5/v7 through SciPy, v7.3 (HDF5) through h5py.

Each numeric vector of the record's length (N-by-1 or 1-by-N) becomes a column
named like the variable; each 1-by-1 numeric variable (a gain, a sample time)
is kept as a constant. Text, structs, cells and empty arrays are left out
silently; matrices, complex arrays and vectors of another length are left out
with a :class:`~condmon.errors.DataWarning` naming them.

MATLAB stores a v7.3 file in HDF5 with every array transposed (column-major
order written as row-major): a 24841-by-1 vector is an HDF5 dataset of shape
(1, 24841). The reader transposes each dataset back and takes the class from
its ``MATLAB_class`` attribute.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from condmon.errors import DataError
from condmon.io.raw import RawRecord, select_vectors

__all__ = ["read_mat", "is_hdf5"]

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: MATLAB classes read as numbers; ``logical`` is read as 0/1.
NUMERIC_CLASSES = frozenset({"double", "single", "logical", "int8", "int16", "int32", "int64",
                             "uint8", "uint16", "uint32", "uint64"})
#: v5 data types of the elements inside a matrix (miINT8 ... miUTF32, miMATRIX).
_V5_DATA_TYPES = frozenset({1, 2, 3, 4, 5, 6, 7, 9, 12, 13, 14, 16, 17, 18})
_MI_MATRIX, _MI_COMPRESSED = 14, 15
_MAX_DEPTH = 64


def is_hdf5(path: Path) -> bool:
    """True when the file is HDF5 (a MATLAB v7.3 file has its 512-byte header first).

    Example
    -------
    >>> import tempfile
    >>> d = tempfile.TemporaryDirectory()
    >>> p = Path(d.name) / "x.mat"
    >>> _ = p.write_bytes(b"MATLAB 5.0 MAT-file")
    >>> is_hdf5(p)
    False
    >>> d.cleanup()
    """
    with path.open("rb") as fh:
        head = fh.read(520)
    return head[:8] == _HDF5_SIGNATURE or head[512:520] == _HDF5_SIGNATURE


def read_mat(path: Path) -> RawRecord:
    """Read a MATLAB record: vectors as columns, scalars as constants.

    Parameters
    ----------
    path : Path
        A ``.mat`` file, any version (v7.3 files are HDF5).

    Returns
    -------
    RawRecord
        ``frame`` with one column per vector variable (in file order),
        ``constants`` with the 1x1 variables.

    Raises
    ------
    DataError
        No numeric vector in the file, or the file is not a MATLAB file.

    Example
    -------
    >>> import tempfile, scipy.io
    >>> d = tempfile.TemporaryDirectory()
    >>> p = Path(d.name) / "rig.mat"
    >>> scipy.io.savemat(p, {"t": np.arange(4.0)[:, None] * 1e-3, "vir": np.ones((4, 1)),
    ...                      "kp": 160.18, "label": "EMPS"})
    >>> raw = read_mat(p)
    >>> list(raw.frame.columns), raw.constants
    (['t', 'vir'], {'kp': 160.18})
    >>> d.cleanup()
    """
    items = _read_hdf5(path) if is_hdf5(path) else _read_v5(path)
    columns, constants, ignored = select_vectors(items, path, "variable")
    return RawRecord(pd.DataFrame(columns), constants=constants, ignored=ignored)


def _read_v5(path: Path) -> dict[str, np.ndarray[Any, Any]]:
    import scipy.io
    import scipy.sparse

    _check_v5_structure(path)
    try:
        data = scipy.io.loadmat(path, squeeze_me=False, mat_dtype=False)
    except NotImplementedError:  # v7.3, though its HDF5 signature was not found
        raise DataError(f"{path}: a MATLAB v7.3 file that is not valid HDF5") from None
    items: dict[str, np.ndarray[Any, Any]] = {}
    for name, value in data.items():
        if name.startswith("__"):  # __header__, __version__, __globals__
            continue
        if scipy.sparse.issparse(value):
            shape = tuple(int(n) for n in value.shape)
            # a sparse vector is read; a sparse matrix is named as a matrix, never densified
            items[name] = (np.asarray(value.toarray()) if min(shape) == 1
                           else np.broadcast_to(np.zeros(1), shape))
        elif isinstance(value, np.ndarray):
            items[name] = value
        else:
            items[name] = np.array([], dtype=object)
    return items


def _read_hdf5(path: Path) -> dict[str, np.ndarray[Any, Any]]:
    import h5py

    items: dict[str, np.ndarray[Any, Any]] = {}
    with h5py.File(path, "r") as f:
        for name in f:
            if name.startswith("#"):  # '#refs#', '#subsystem#': MATLAB's own storage
                continue
            node = f.get(name)  # None for a broken link: left out like a group
            if not isinstance(node, h5py.Dataset):  # a struct or an object: a group
                items[name] = np.array([], dtype=object)
                continue
            cls = node.attrs.get("MATLAB_class", b"")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            if cls and cls not in NUMERIC_CLASSES:  # char, cell, struct, function_handle ...
                items[name] = np.array([], dtype=object)
                continue
            if node.attrs.get("MATLAB_empty", 0):
                items[name] = np.zeros(0)
                continue
            arr = np.asarray(node[()])
            if arr.dtype.names and {"real", "imag"} <= set(arr.dtype.names):
                arr = arr["real"] + 1j * arr["imag"]
            arr = arr.T  # MATLAB writes column-major: HDF5's shape is MATLAB's reversed
            items[name] = arr.astype(bool) if cls == "logical" else arr
    return items


def _check_v5_structure(path: Path) -> None:
    """Walk a v5 file's element tags before SciPy reads it.

    SciPy's compiled reader trusts the data type in each element's tag and
    crashes the interpreter on an unknown one (a corrupt file); this walk
    refuses such a file with a DataError first. Files without a v5 header
    (v4) are left to SciPy.
    """
    data = path.read_bytes()
    if len(data) < 128 or data[126:128] not in (b"IM", b"MI"):
        return
    _walk_v5(data, 128, "<" if data[126:128] == b"IM" else ">", path, in_matrix=False, depth=0)


def _walk_v5(buf: bytes, off: int, order: str, path: Path, *, in_matrix: bool,
             depth: int) -> None:
    """Check every top-level element (``in_matrix`` False) or matrix sub-element."""
    if depth > _MAX_DEPTH:
        raise DataError(f"{path}: corrupt MATLAB file: elements nested too deep")
    for word, start, end in _elements(buf, off, order, path, small=in_matrix):
        if word == _MI_COMPRESSED and not in_matrix:
            try:
                inner = zlib.decompressobj().decompress(buf[start:end])
            except zlib.error:
                raise DataError(f"{path}: corrupt MATLAB file: compressed variable at byte "
                                f"{start - 8} does not decompress") from None
            _walk_v5(inner, 0, order, path, in_matrix=False, depth=depth + 1)
        elif word == _MI_MATRIX:
            _check_matrix(buf[start:end], order, path, depth + 1)
        elif not (in_matrix and word in _V5_DATA_TYPES):
            raise DataError(f"{path}: corrupt MATLAB file: unknown element type {word} "
                            f"at byte {start - 8}")


def _elements(buf: bytes, off: int, order: str, path: Path, *, small: bool
              ) -> list[tuple[int, int, int]]:
    """(data type, start, end) of each element from ``off`` on."""
    out: list[tuple[int, int, int]] = []
    while off < len(buf):
        if len(buf) - off < 8:
            raise DataError(f"{path}: corrupt MATLAB file: truncated element at byte {off}")
        word, nbytes = struct.unpack_from(order + "II", buf, off)
        if small and word >> 16:  # small data element: type and size in one word
            if word & 0xFFFF not in _V5_DATA_TYPES or word >> 16 > 4:
                raise DataError(f"{path}: corrupt MATLAB file: bad element at byte {off}")
            out.append((word & 0xFFFF, off + 4, off + 4 + (word >> 16)))
            off += 8
            continue
        start, end = off + 8, off + 8 + nbytes
        if end > len(buf):
            raise DataError(f"{path}: corrupt MATLAB file: element at byte {off} runs past "
                            "the end of its data (truncated?)")
        out.append((word, start, end))
        off = end if word in (_MI_MATRIX, _MI_COMPRESSED) else start + (nbytes + 7) // 8 * 8
    return out


def _check_matrix(buf: bytes, order: str, path: Path, depth: int) -> None:
    """A matrix has the parts its array flags promise (SciPy reads them unchecked)."""
    _walk_v5(buf, 0, order, path, in_matrix=True, depth=depth)
    parts = _elements(buf, 0, order, path, small=True)
    bad = DataError(f"{path}: corrupt MATLAB file: a variable's parts do not match its header")
    if not parts:
        return  # an empty cell element
    if parts[0][0] != 6 or parts[0][2] - parts[0][1] != 8:
        raise bad
    flags = struct.unpack_from(order + "I", buf, parts[0][1])[0]
    cls, is_complex = flags & 0xFF, bool(flags & 0x0800)
    if cls in (16, 17):  # function handles, opaque objects: no dimensions
        return
    if len(parts) < 3 or parts[1][0] != 5 or (parts[1][2] - parts[1][1]) % 4:
        raise bad
    n_dims = (parts[1][2] - parts[1][1]) // 4
    count = int(np.prod(struct.unpack_from(f"{order}{n_dims}i", buf, parts[1][1]),
                        dtype=np.float64)) if n_dims else 0
    if cls == 4 or 6 <= cls <= 15:  # char, numeric: real part, imaginary if complex
        need = 4 + is_complex
    elif cls == 5:  # sparse: row indices, column pointers, values
        need = 6 + is_complex
    elif cls in (1, 2, 3):  # cell, struct, object: nested matrices
        matrices = sum(1 for p in parts[3:] if p[0] == _MI_MATRIX)
        fields = 1
        if cls != 1:
            names = [p for p in parts[3:] if p[0] != _MI_MATRIX]
            if len(names) < 2:
                raise bad
            length = int(np.frombuffer(buf[names[-2][1]:names[-2][2]],
                                       dtype=order + "i4")[:1].sum())
            fields = (names[-1][2] - names[-1][1]) // length if length > 0 else 0
        if matrices < count * fields:
            raise bad
        return
    else:
        raise bad
    if len(parts) < need or any(p[0] == _MI_MATRIX for p in parts[3:need]):
        raise bad
