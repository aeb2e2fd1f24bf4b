"""Parquet takes in chunks: a take of any length through a few MB of memory that is reused.

:func:`open_parquet` checks a file's columns (as :func:`riderlive.framefile.read_frames`
does); :func:`read_chunks` yields its frames :data:`CHUNK` at a time, each checked for
empty cells and NaN or inf and named by the file's row (1 = the first frame) and column,
exactly as a whole read would; :func:`write_chunks` writes columns chunk by chunk into
one Parquet file (row groups of :data:`ROW_GROUP` frames, no compression, statistics on:
:data:`riderlive.framefile.PARQUET_COMPRESSION`), beside the target and renamed at the
end, so a failure at any chunk leaves nothing partial under the output's name.

Why chunks: a whole 10^7-frame take is 2 GB in and 3 GB out, and every fresh page of
those arrays costs the kernel a page fault (most of a whole-take bake's time was system
time). Chunks of 65536 frames come from and go back to the allocator warm.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from riderlive.framefile import (
    PARQUET_COMPRESSION,
    TIME,
    FrameFileError,
    FrameTable,
    atomic_path,
    parquet_names,
    parquet_table,
)

FloatArray = npt.NDArray[np.float64]
CHUNK = 65536
"""Frames per chunk: the rules' 37 output channels are 19 MB, under glibc's largest mmap threshold
(32 MB), so each chunk reuses the previous one's memory instead of faulting in fresh pages."""
ROW_GROUP = 262144
"""Frames per written row group (polars' default for whole files: 512^2)."""


@dataclass(frozen=True)
class ParquetTake:
    """A checked Parquet file: its columns in file order (``t`` included) and its number of frames."""

    source: str
    path: Path
    names: tuple[str, ...]
    frames: int

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(n for n in self.names if n != TIME)


def open_parquet(path: str, required: Iterable[str] = ()) -> ParquetTake:
    """Check the file's schema (names, types, ``required`` channels) and count its frames."""
    import polars as pl

    file = Path(path)
    if not file.is_file():
        raise FrameFileError(path, "file not found")
    names = parquet_names(path, file, tuple(required))
    try:
        frames = pl.scan_parquet(file).select(pl.len()).collect().item()
    except Exception as exc:  # a damaged file: its schema read, its metadata did not
        raise FrameFileError(path, f"unreadable Parquet data ({type(exc).__name__}: {exc})") from None
    return ParquetTake(path, file, tuple(names), int(frames))


def read_columns(take: ParquetTake, names: Iterable[str]) -> FrameTable:
    """Whole columns of ``take`` (those it has of ``names``), checked like a whole read."""
    import polars as pl

    wanted = [n for n in names if n in take.names and n != TIME]
    frame = pl.read_parquet(take.path, columns=wanted)
    return parquet_table(take.source, frame, wanted)


def read_chunks(take: ParquetTake, chunk: int = CHUNK) -> Iterator[FrameTable]:
    """The take's frames, ``chunk`` at a time, each checked (errors name the file's row and column)."""
    import polars as pl

    first_row = 1
    try:
        batches = iter(pl.scan_parquet(take.path).collect_batches(chunk_size=chunk))
        while True:
            try:
                frame = next(batches)
            except StopIteration:
                return
            table = parquet_table(take.source, frame, take.names, first_row)
            first_row += len(table)
            yield table
    except FrameFileError:
        raise
    except Exception as exc:  # a damaged file: its metadata read, its data did not
        raise FrameFileError(take.source, f"unreadable Parquet data ({type(exc).__name__}: {exc})") from None


def write_chunks(
    path: str,
    names: Iterable[str],
    chunks: Iterable[Mapping[str, FloatArray]],
    progress: Callable[[int], object] | None = None,
) -> None:
    """Write ``chunks`` (each: ``names`` -> equal-length float64 columns) as one Parquet file, atomically.

    An exception raised while producing a chunk propagates unchanged, and nothing is left
    under ``path`` (or beside it).
    """
    import polars as pl
    from polars.io.plugins import register_io_source

    columns = list(names)
    failed: list[BaseException] = []

    def source(*_: object) -> Iterator[pl.DataFrame]:
        try:
            for chunk in chunks:
                frame = pl.DataFrame({name: chunk[name] for name in columns})
                if progress:
                    progress(frame.height)
                yield frame
        except BaseException as exc:  # handed to the caller below: polars would wrap it
            failed.append(exc)
            raise

    lazy = register_io_source(source, schema={name: pl.Float64 for name in columns})
    with atomic_path(path) as tmp:
        try:
            lazy.sink_parquet(tmp, compression=PARQUET_COMPRESSION, statistics=True, row_group_size=ROW_GROUP)
        except Exception:
            if failed:
                raise failed[0] from None
            raise
