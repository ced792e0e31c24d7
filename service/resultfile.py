"""A job's result file, written while the schedule is computed and read without loading it.

The file is the ``.npz`` the service has always stored (an uncompressed zip of ``.npy`` members: the float64
columns ``c0``, ``c1``, ... in API order, and ``__meta__``, the JSON of summary, diagnostics and the column
names as uint8), so ``numpy.load`` reads it as before and files stored by earlier versions load here.

- ``ResultWriter``: the solver process appends each released block of samples to one raw file per column
  (``<result>.parts/``), so what it holds is one block, not the schedule; ``finish`` copies the columns into the
  zip (``<result>.tmp``, then renamed) in ``COPY_BYTES`` pieces and removes the parts.
- ``load``: the columns as read-only arrays over a memory map of the file (no copy: the pages are the kernel's
  page cache, read as a download reaches them), the metadata parsed.  Members stored compressed (never by this
  service) are read into memory instead.
"""

from __future__ import annotations

import io
import json
import mmap
import shutil
import struct
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: Bytes copied at a time from a column's raw part into the zip.
COPY_BYTES = 8 * 2**20
#: The local file header of a zip member: signature, versions, flags, method, times, crc, sizes, name and
#: extra lengths (PKWARE APPNOTE 4.3.7); the member's data follow its name and extra field.
_LOCAL_HEADER = struct.Struct("<4s5H3L2H")
_LOCAL_SIGNATURE = b"PK\x03\x04"


class ResultFileError(Exception):
    """A stored result that cannot be read as one (``path``: the file); the service answers it as an internal
    error (problem+json, 500): the file is the service's, not the client's."""

    def __init__(self, message: str, path: Path) -> None:
        super().__init__(f"{path.name}: {message}")
        self.path = path


def parts_dir(path: Path) -> Path:
    """Where ``ResultWriter`` keeps the raw columns of ``path`` while it writes."""
    return path.with_name(path.name + ".parts")


def tmp_path(path: Path) -> Path:
    """The zip being assembled before it is renamed to ``path``."""
    return path.with_name(path.name + ".tmp")


def remove_partial(path: Path) -> None:
    """Remove what an interrupted ``ResultWriter`` for ``path`` left (its parts and unfinished zip)."""
    shutil.rmtree(parts_dir(path), ignore_errors=True)
    tmp_path(path).unlink(missing_ok=True)


class ResultWriter:
    """Appends blocks of equal-length float64 columns to ``path``'s parts; ``finish`` makes the ``.npz``.

    Columns: the names and order of the first block; every later block must have the same.  Not thread-safe.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._dir = parts_dir(self.path)
        remove_partial(self.path)
        self._dir.mkdir(parents=True)
        self.names: list[str] = []
        self.rows = 0
        self._files: list[Any] = []

    def append(self, columns: dict[str, FloatArray]) -> None:
        names = list(columns)
        if not self.names:
            self.names = names
            self._files = [open(self._dir / f"c{i}.raw", "wb") for i in range(len(names))]
        elif names != self.names:
            raise ValueError(f"block columns {names} differ from the first block's {self.names}")
        n = {len(c) for c in columns.values()}
        if len(n) != 1:
            raise ValueError(f"block columns of unequal lengths {sorted(n)}")
        for fh, name in zip(self._files, names, strict=True):
            fh.write(np.ascontiguousarray(columns[name], dtype="<f8").tobytes())
        self.rows += n.pop()

    def finish(self, summary: dict[str, Any], diagnostics: dict[str, Any]) -> Path:
        """Write the ``.npz`` (atomically: a temporary name, then renamed) and remove the parts."""
        for fh in self._files:
            fh.close()
        tmp = tmp_path(self.path)
        meta = json.dumps({"summary": summary, "diagnostics": diagnostics, "columns": self.names}).encode()
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for i in range(len(self.names)):
                _member(zf, f"c{i}.npy", np.dtype("<f8"), self.rows, self._dir / f"c{i}.raw")
            _member_bytes(zf, "__meta__.npy", meta)
        tmp.replace(self.path)
        shutil.rmtree(self._dir, ignore_errors=True)
        return self.path

    def abort(self) -> None:
        for fh in self._files:
            fh.close()
        remove_partial(self.path)


def _npy_header(dtype: np.dtype[Any], n: int) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": np.lib.format.dtype_to_descr(dtype),
                                                "fortran_order": False, "shape": (n,)})
    return buf.getvalue()


def _member(zf: zipfile.ZipFile, name: str, dtype: np.dtype[Any], n: int, raw: Path) -> None:
    header = _npy_header(dtype, n)
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_STORED
    info.file_size = len(header) + n * dtype.itemsize  # (known up front: zip64 fields when it needs them)
    with zf.open(info, "w") as out, open(raw, "rb") as src:
        out.write(header)
        while chunk := src.read(COPY_BYTES):
            out.write(chunk)


def _member_bytes(zf: zipfile.ZipFile, name: str, data: bytes) -> None:
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_STORED
    zf.writestr(info, _npy_header(np.dtype(np.uint8), len(data)) + data)


def load(path: Path) -> tuple[dict[str, Any], dict[str, Any], dict[str, FloatArray]]:
    """(summary, diagnostics, columns) of a stored result; the columns are read-only views of a memory map."""
    path = Path(path)
    with open(path, "rb") as fh, zipfile.ZipFile(fh) as zf:
        try:
            meta = json.loads(bytes(_read_member(zf, "__meta__.npy")).decode())
            names = list(meta["columns"])
        except (KeyError, ValueError) as exc:
            raise ResultFileError(f"no readable metadata ({exc})", path) from None
        infos = {i.filename: i for i in zf.infolist()}
        # (never of zero bytes: a zip holds at least its end record)
        mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        cols: dict[str, FloatArray] = {}
        for i, name in enumerate(names):
            info = infos.get(f"c{i}.npy")
            if info is None:
                raise ResultFileError(f"column {name!r} (c{i}.npy) is missing", path)
            if info.compress_type != zipfile.ZIP_STORED:
                cols[name] = np.asarray(_read_member(zf, info.filename), dtype=np.float64)
                continue
            cols[name] = _mapped(mm, fh, info, path)
    return meta["summary"], meta["diagnostics"], cols


def _read_member(zf: zipfile.ZipFile, name: str) -> NDArray[Any]:
    with zf.open(name) as f:
        return np.asarray(np.lib.format.read_array(f, allow_pickle=False))


def _mapped(mm: mmap.mmap, fh: Any, info: zipfile.ZipInfo, path: Path) -> FloatArray:
    fh.seek(info.header_offset)
    head = _LOCAL_HEADER.unpack(fh.read(_LOCAL_HEADER.size))
    if head[0] != _LOCAL_SIGNATURE:
        raise ResultFileError(f"{info.filename}: no local file header at {info.header_offset}", path)
    start = info.header_offset + _LOCAL_HEADER.size + head[-2] + head[-1]
    fh.seek(start)
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
    else:
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
    if len(shape) != 1 or dtype != np.dtype("<f8") or fortran:
        raise ResultFileError(f"{info.filename}: shape {shape}, dtype {dtype}; float64 vectors expected", path)
    offset = fh.tell()
    if offset + shape[0] * 8 > len(mm):
        raise ResultFileError(f"{info.filename}: {shape[0]} values run past the end of the file", path)
    out: FloatArray = np.frombuffer(mm, dtype="<f8", count=shape[0], offset=offset)
    return out
