"""Frame files: CSV, JSONL and Parquet takes of horse or rider channels, read and written.

CSV: a header of channel names, an optional ``t`` column (seconds), one frame per
line. JSONL: one object per line with ``t`` and channel values. Parquet (``.parquet``,
``.pq``): one numeric column per channel (float64 written; any float or integer type
read), an optional ``t`` column; binary, so a 10^7-frame take reads and writes
without parsing text. ``-`` reads stdin or writes stdout. Reading validates
everything once at the edge: an unknown, duplicate or missing column, a cell that is
not a number (Parquet: a column that is not numeric), an empty cell, NaN or inf raise
:class:`FrameFileError` naming the file, the line (CSV, JSONL; the header is line 1)
or row (Parquet; the first frame is row 1) and the column. Channel values come back
as an (N, C) array whose columns are contiguous. Writing goes to a file beside the
target and is renamed at the end, so a failed run leaves nothing partial under the
output's name.
"""

from __future__ import annotations

import csv
import io
import os
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Final

import numpy as np
import numpy.typing as npt
import orjson

from riderlive.channels import HORSE, HORSE_INDEX, is_known

DEFAULT_RATE = 120.0
"""Frame rate assumed for a take without a ``t`` column (Hz): ``bake``, ``tail``, ``platform``."""

if TYPE_CHECKING:
    import polars as pl

FloatArray = npt.NDArray[np.float64]
TIME = "t"
FORMATS = ("csv", "jsonl", "parquet")
"""The frame file formats (``--format`` choices)."""
PARQUET_COMPRESSION: Final = "uncompressed"
"""Parquet compression on write: none. float64 motion channels barely compress (lz4: 2 % smaller on a
random take) while lz4 costs ~0.15 s per GB each way; every Parquet reader reads uncompressed pages."""


class FrameFileError(ValueError):
    """Bad frame data; the message names the file, line and column."""

    def __init__(
        self, source: str, message: str, line: int | None = None, column: str | None = None, row: int | None = None
    ) -> None:
        self.source, self.line, self.column, self.row = source, line, column, row
        where = source if line is None else f"{source}:{line}"
        if row is not None:
            where += f": row {row}"
        if column is not None:
            where += f": column {column!r}"
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class FrameTable:
    """Frames as columns: ``values`` is (N, len(names)); ``t`` is (N,) or None."""

    names: tuple[str, ...]
    values: FloatArray
    t: FloatArray | None = None

    def __len__(self) -> int:
        return int(self.values.shape[0])

    def column(self, name: str) -> FloatArray:
        if name == TIME and self.t is not None:
            return self.t
        return self.values[:, self.names.index(name)]

    def times(self, rate: float) -> FloatArray:
        """The ``t`` column, or ``i / rate`` when the file had none."""
        return self.t if self.t is not None else np.arange(len(self), dtype=np.float64) / rate


def file_format(path: str, override: str | None = None) -> str:
    """``csv``, ``jsonl`` or ``parquet`` from an explicit choice or the file's extension."""
    if override:
        return override
    suffix = Path(path).suffix.lower()
    if suffix in (".jsonl", ".ndjson"):
        return "jsonl"
    if suffix in (".parquet", ".pq"):
        return "parquet"
    if suffix == ".csv" or path == "-":
        return "csv"
    raise FrameFileError(path, f"unknown file type {suffix!r} (use .csv, .jsonl or .parquet)")


def _check_names(source: str, names: Sequence[str], required: Iterable[str], line: int | None = 1) -> None:
    seen: set[str] = set()
    for name in names:
        if name != TIME and not is_known(name):
            raise FrameFileError(source, "unknown channel", line=line, column=name)
        if name in seen:
            raise FrameFileError(source, "duplicate column", line=line, column=name)
        seen.add(name)
    missing = [r for r in required if r not in seen]
    if missing:
        raise FrameFileError(source, f"missing required channel(s): {', '.join(missing)}", line=line)


def _first_bad_cell(source: str, text: str, names: Sequence[str]) -> FrameFileError:
    """Walk the CSV slowly to name the first cell that is not a finite number."""
    reader = csv.reader(io.StringIO(text))
    next(reader, None)
    for line_no, row in enumerate(reader, start=2):
        if len(row) != len(names):
            return FrameFileError(source, f"expected {len(names)} cells, found {len(row)}", line=line_no)
        for name, cell in zip(names, row, strict=True):
            try:
                value = float(cell)
            except ValueError:
                return FrameFileError(source, f"not a number: {cell!r}", line=line_no, column=name)
            if not np.isfinite(value):
                return FrameFileError(source, f"not finite: {cell.strip()}", line=line_no, column=name)
    return FrameFileError(source, "could not be parsed as CSV")


def _read_bytes(path: str) -> bytes:
    if path == "-":
        return sys.stdin.buffer.read()
    try:
        return Path(path).read_bytes()
    except FileNotFoundError:
        raise FrameFileError(path, "file not found") from None
    except IsADirectoryError:
        raise FrameFileError(path, "is a directory") from None


def _decode(source: str, data: bytes) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FrameFileError(source, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def _text(source: str, data: bytes | Path) -> str:
    return _decode(source, data.read_bytes() if isinstance(data, Path) else data)


def _read_csv(source: str, data: bytes | Path, required: Iterable[str]) -> FrameTable:
    """Parse with polars (fast, memory-mapped for files); on any doubt, walk the text."""
    import polars as pl

    if isinstance(data, Path):
        with data.open("rb") as fh:
            first_line = fh.readline()
    else:
        first_line = data.split(b"\n", 1)[0]
    header = next(csv.reader([_decode(source, first_line).strip("\r\ufeff")]), None)
    if not header:
        raise FrameFileError(source, "empty file: expected a header of channel names", line=1)
    names = [h.strip() for h in header]
    _check_names(source, names, required)
    try:
        frame = pl.read_csv(data, schema={n: pl.Float64 for n in names}, has_header=True, new_columns=names)
    except Exception:  # any parse failure gets an exact location below
        raise _first_bad_cell(source, _text(source, data), names) from None
    channels = [n for n in names if n != TIME]
    values = frame.select(channels).to_numpy(order="fortran").astype(np.float64, copy=False)
    times = frame[TIME].to_numpy().astype(np.float64) if TIME in names else None
    del frame
    finite = np.isfinite(values).all() and (times is None or np.isfinite(times).all())
    if not finite:  # NaN, inf, or an empty cell read as null
        raise _first_bad_cell(source, _text(source, data), names)
    return FrameTable(tuple(channels), values, times)


def _split_time(names: list[str], data: FloatArray) -> FrameTable:
    if TIME in names:
        ti = names.index(TIME)
        keep = [i for i in range(len(names)) if i != ti]
        return FrameTable(tuple(names[i] for i in keep), np.ascontiguousarray(data[:, keep]), data[:, ti].copy())
    return FrameTable(tuple(names), data)


def _read_jsonl(source: str, text: str, required: Iterable[str]) -> FrameTable:
    names: list[str] | None = None
    rows: list[list[float]] = []
    for line_no, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            obj = orjson.loads(line)
        except orjson.JSONDecodeError as exc:
            raise FrameFileError(source, f"not JSON: {exc}", line=line_no) from None
        if not isinstance(obj, dict):
            raise FrameFileError(source, "expected a JSON object", line=line_no)
        if names is None:
            names = list(obj)
            _check_names(source, names, required)
        elif set(obj) != set(names):
            odd = sorted(set(obj) ^ set(names))[0]
            raise FrameFileError(source, "channels differ from the first frame", line=line_no, column=odd)
        row = []
        for name in names:
            value = obj[name]
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise FrameFileError(source, f"not a number: {value!r}", line=line_no, column=name)
            if not np.isfinite(value):
                raise FrameFileError(source, f"not finite: {value!r}", line=line_no, column=name)
            row.append(float(value))
        rows.append(row)
    if names is None:
        raise FrameFileError(source, "empty file: no frames")
    return _split_time(names, np.array(rows, dtype=np.float64).reshape(len(rows), len(names)))


def _read_parquet(source: str, data: bytes | Path, required: Iterable[str]) -> FrameTable:
    """Read with polars (columnar, multi-threaded), then check names, types, empty cells and finiteness."""
    import polars as pl

    raw = io.BytesIO(data) if isinstance(data, bytes) else data
    names = parquet_names(source, raw, required)
    if isinstance(raw, io.BytesIO):
        raw.seek(0)
    try:
        frame = pl.read_parquet(raw)
    except Exception as exc:  # a damaged file: its metadata read, its data did not
        raise FrameFileError(source, f"unreadable Parquet data ({type(exc).__name__}: {exc})") from None
    return parquet_table(source, frame, names)


def parquet_names(source: str, raw: IO[bytes] | Path, required: Iterable[str]) -> list[str]:
    """The column names of a Parquet file, checked: known channels, no duplicates, numbers only."""
    import polars as pl

    try:
        schema = pl.read_parquet_schema(raw)
    except Exception as exc:  # polars raises its own error types for a file that is not Parquet
        raise FrameFileError(source, f"not a Parquet file ({type(exc).__name__})") from None
    names = list(schema)
    _check_names(source, names, required, line=None)
    for name, dtype in schema.items():
        if not (dtype.is_float() or dtype.is_integer()):
            raise FrameFileError(source, f"not numbers: the column holds {dtype}", column=name)
    return names


def parquet_table(source: str, frame: pl.DataFrame, names: Sequence[str], first_row: int = 1) -> FrameTable:
    """``frame`` (the rows from ``first_row`` on, 1 = the file's first) as a table, or the first bad cell named."""
    import polars as pl

    for name, nulls in zip(names, frame.null_count().row(0), strict=True):
        if nulls:
            row = int(frame[name].is_null().arg_true()[0]) + first_row
            raise FrameFileError(source, "empty cell", row=row, column=name)
    channels = [n for n in names if n != TIME]
    values = frame.select(pl.col(channels).cast(pl.Float64)).to_numpy(order="fortran")
    times = frame[TIME].cast(pl.Float64).to_numpy() if TIME in names else None
    del frame
    for name, column in ([(TIME, times)] if times is not None else []) + list(zip(channels, values.T, strict=True)):
        _check_finite(source, name, column, first_row)
    return FrameTable(tuple(channels), values, times)


def _check_finite(source: str, name: str, column: FloatArray, first_row: int = 1) -> None:
    """Raise naming the first row that is NaN or inf. The sum is finite only if every value is (fast path;
    a sum that overflows is then checked value by value)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(np.add.reduce(column)):
            return
    bad = np.flatnonzero(~np.isfinite(column))
    if len(bad):
        raise FrameFileError(source, f"not finite: {column[bad[0]]}", row=int(bad[0]) + first_row, column=name)


def read_frames(path: str, required: Iterable[str] = (), fmt: str | None = None) -> FrameTable:
    """Read a whole frame file, validated; see the module docstring."""
    kind = file_format(path, fmt)
    source = "<stdin>" if path == "-" else path
    required = tuple(required)
    if kind in ("csv", "parquet"):
        if path != "-" and not Path(path).is_file():
            raise FrameFileError(path, "file not found")
        read = _read_csv if kind == "csv" else _read_parquet
        return read(source, _read_bytes(path) if path == "-" else Path(path), required)
    return _read_jsonl(source, _decode(source, _read_bytes(path)), required)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str) -> Iterator[Path]:
    """Yield the path of a file beside ``path`` that replaces it only on success."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent or ".")
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def _atomic_binary(path: str) -> Iterator[IO[bytes]]:
    """Yield a file beside ``path`` that replaces it only on success (stdout for ``-``)."""
    if path == "-":
        yield sys.stdout.buffer
        sys.stdout.buffer.flush()
        return
    with atomic_path(path) as tmp, tmp.open("wb") as fh:
        yield fh


ProgressCallback = Callable[[int], None]
WRITE_SLICE = 65536


def write_frames(
    path: str, table: FrameTable, fmt: str | None = None, progress: ProgressCallback | None = None
) -> None:
    """Write ``table`` to ``path`` (atomically), calling ``progress(frames)`` as it goes."""
    kind = file_format(path, fmt)
    names = ([TIME] if table.t is not None else []) + list(table.names)
    columns = ([table.t] if table.t is not None else []) + [table.values[:, i] for i in range(len(table.names))]
    if kind == "parquet":
        _write_parquet(path, dict(zip(names, columns, strict=True)))
        if progress:
            progress(len(table))
        return
    with _atomic_binary(path) as fh:
        if kind == "csv":
            import polars as pl

            frame = pl.DataFrame(dict(zip(names, columns, strict=True)))
            for start in range(0, max(len(table), 1), WRITE_SLICE):
                part = frame.slice(start, WRITE_SLICE)
                part.write_csv(fh, include_header=start == 0)
                if progress:
                    progress(part.height)
        else:
            for start in range(0, len(table), WRITE_SLICE):
                block = np.column_stack([c[start : start + WRITE_SLICE] for c in columns]).tolist()
                fh.write(b"".join(orjson.dumps(dict(zip(names, row, strict=True))) + b"\n" for row in block))
                if progress:
                    progress(len(block))


def _write_parquet(path: str, columns: dict[str, FloatArray]) -> None:
    """One Parquet file, written by polars from the columns (no copy when they are contiguous)."""
    import polars as pl

    frame = pl.DataFrame(columns)
    if path == "-":
        buffer = io.BytesIO()
        frame.write_parquet(buffer, compression=PARQUET_COMPRESSION)
        sys.stdout.buffer.write(buffer.getvalue())
        sys.stdout.buffer.flush()
        return
    with atomic_path(path) as tmp:
        frame.write_parquet(tmp, compression=PARQUET_COMPRESSION)


def horse_matrix(table: FrameTable) -> npt.NDArray[np.float64]:
    """The table's horse channels in canonical order (``channels.HORSE``); omitted channels are zero."""
    out = np.zeros((len(table), len(HORSE)), dtype=np.float64)
    for j, name in enumerate(table.names):
        if name in HORSE_INDEX:
            out[:, HORSE_INDEX[name]] = table.values[:, j]
    return out
