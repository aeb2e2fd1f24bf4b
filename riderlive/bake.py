"""Offline baking: a horse take in, the rider's channels out (``riderlive bake``).

``--timings`` prints where the time went: reading (parsing and checking the file),
the rules (of which the smoothing filters, when on), writing. Parquet in and out
(``.parquet``) skips text parsing and formatting, and streams: a horse take goes
through in chunks of :data:`riderlive.parquetstream.CHUNK` frames (read, rules,
filters carrying their state, written), so memory stays small and is reused; reading
and writing then overlap the rules, and ``write`` is the time left over. A take of
10^6 frames or more runs the compiled rules (:data:`riderlive.rules.engine.COMPILED_FROM`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from riderlive.channels import HORSE_INDEX, RIDER_INDEX, RIDER_NAMES, RIDER_PART_NAMES
from riderlive.configfile import ConfigError
from riderlive.framefile import (
    DEFAULT_RATE,
    FORMATS,
    FrameFileError,
    FrameTable,
    file_format,
    read_frames,
    write_frames,
)
from riderlive.frameunits import HOOF_HEIGHTS, recorded_scale, resolve_scale
from riderlive.parquetstream import ParquetTake, open_parquet, read_chunks, read_columns, write_chunks
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.engine import COMPILED_FROM, RiderModel
from riderlive.rules.filters import SeriesState, damp_rows, spring_rows
from riderlive.rules.kuhnel2003 import RULE_INPUTS
from riderlive.rules.params import load_preset
from riderlive.rules.parts import RiderParts
from riderlive.saddle.takes import add_point_arguments
from riderlive.units import RIG_UNITS_PER_METRE, metres_per_unit


def bake_table(
    table: FrameTable,
    model: RiderModel,
    channels: Sequence[str] | None = None,
    rate: float = DEFAULT_RATE,
) -> FrameTable:
    """Evaluate the rules on every frame of ``table``; keep ``channels`` (all if None)."""
    columns = {name: table.column(name) for name in table.names if name in HORSE_INDEX}
    rider = model.evaluate_columns(columns, len(table))  # (N, C), each channel contiguous
    times = table.times(rate)
    Filters(model).run(rider.T, times)
    if channels and any(name in RIDER_PART_NAMES for name in channels):  # the rider parts, asked for by name
        horse = np.zeros((len(table), len(HORSE_INDEX)))
        for name, column in columns.items():
            horse[:, HORSE_INDEX[name]] = column
        parts = RiderParts(model.params, metres_per_unit(model.scale)).evaluate_batch(horse, rider)
        rider = np.column_stack([rider, parts])
        index = {**RIDER_INDEX, **{n: len(RIDER_NAMES) + i for i, n in enumerate(RIDER_PART_NAMES)}}
        return FrameTable(tuple(channels), np.asfortranarray(rider[:, [index[n] for n in channels]]), times)
    names = tuple(channels) if channels else RIDER_NAMES
    picked = rider if names == RIDER_NAMES else np.asfortranarray(rider[:, [RIDER_INDEX[n] for n in names]])
    return FrameTable(names, picked, times)


def with_saddle(rider: FrameTable, saddle: FrameTable) -> FrameTable:
    """``rider``'s columns followed by the saddle's six (same rows)."""
    return FrameTable(rider.names + saddle.names, np.column_stack([rider.values, saddle.values]), rider.t)


class Filters:
    """The preset's smoothing and follow-through over rows of frames, piece by piece (state carried)."""

    def __init__(self, model: RiderModel) -> None:
        self.time_constant = model.params.smoothing.time_constant
        self.follow = model.params.follow_through
        self.damper: SeriesState | None = None
        self.spring: SeriesState | None = None
        self.seconds = 0.0

    def run(self, rows: np.ndarray, times: np.ndarray) -> None:
        """Filter ``rows`` (C, n; C-contiguous) in place, the frames after those of the previous call."""
        if self.time_constant <= 0.0 and self.follow.frequency <= 0.0:
            return
        start = time.perf_counter()
        if self.time_constant > 0.0:
            self.damper = damp_rows(rows, times, self.time_constant, self.damper)
        if self.follow.frequency > 0.0:
            self.spring = spring_rows(rows, times, self.follow.frequency, self.follow.damping_ratio, self.spring)
        self.seconds += time.perf_counter() - start


def bake_chunks(  # noqa: PLR0917
    chunks: Iterable[FrameTable],
    model: RiderModel,
    names: Sequence[str],
    rate: float,
    compiled: bool,
    filters: Filters | None = None,
) -> Iterator[dict[str, np.ndarray]]:
    """:func:`bake_table` piece by piece: ``t`` and the rider channels ``names`` of each chunk of frames.

    ``compiled``: the compiled rules kernel (as :func:`bake_table` picks for the whole take's length).
    """
    filters, first = filters or Filters(model), 0
    for table in chunks:
        n = len(table)
        columns = {name: table.column(name) for name in table.names if name in HORSE_INDEX}
        rows = model.evaluate_columns(columns, n, compiled).T  # (C, n), C-contiguous
        times = table.t if table.t is not None else np.arange(first, first + n, dtype=np.float64) / rate
        filters.run(rows, times)
        first += n
        yield {"t": times} | {name: rows[RIDER_INDEX[name]] for name in names}


@dataclass(frozen=True)
class Timings:
    """Seconds spent reading (parsing and checking), in the rules, and writing, for ``frames`` frames.

    ``smoothing``: the part of ``rules`` spent in the smoothing filters (0 when off).
    """

    frames: int
    read: float
    rules: float
    write: float
    smoothing: float = 0.0

    def __str__(self) -> str:
        total = self.read + self.rules + self.write
        filters = f" (smoothing {_seconds(self.smoothing)})" if self.smoothing > 0.0 else ""
        return (
            f"{self.frames:,} frames in {_seconds(total)} ({_throughput(self.frames, total)}): "
            f"read {_seconds(self.read)}, rules {_seconds(self.rules)}{filters}, write {_seconds(self.write)}"
        )


def _seconds(s: float) -> str:
    """A duration with three significant figures in s or ms (a short take's steps take milliseconds)."""
    return f"{s:.3g} s" if s >= 1.0 else f"{s * 1e3:.3g} ms"


def _throughput(frames: int, seconds: float) -> str:
    """Frames per second in the unit that keeps three significant figures: frames/s, k or M frames/s."""
    if seconds <= 0.0:
        return "too fast to time"
    rate = frames / seconds
    for scale, unit in ((1e6, "M frames/s"), (1e3, "k frames/s")):
        if rate >= scale:
            return f"{rate / scale:.3g} {unit}"
    return f"{rate:.3g} frames/s"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="horse or saddle take: .csv, .jsonl or .parquet, or - for stdin")
    parser.add_argument("-o", "--output", required=True, help="rider take to write (.csv, .jsonl, .parquet, or -)")
    parser.add_argument("--preset", default="kuhnel2003", help="preset name or TOML path (default kuhnel2003)")
    parser.add_argument(
        "--scale",
        type=float,
        help="thesis rig units per input length unit (25: metres); default: the input's NAME.json, "
        "else 1 (a saddle take: 25)",
    )
    parser.add_argument("--channels", help="comma-separated rider channels to write (default all)")
    parser.add_argument("--offsets", help="TOML with [offsets] and [gains] per rider channel")
    parser.add_argument("--rate", type=float, default=DEFAULT_RATE, help="Hz, for input without a t column")
    parser.add_argument("--format", choices=FORMATS, help="format for - (default csv)")
    parser.add_argument(
        "--saddle", action="store_true", help="also write the saddle channels (saddle.tx .. rz; m, deg)"
    )
    add_point_arguments(parser)
    parser.add_argument("--timings", action="store_true", help="print where the time went (read, rules, write)")


def run(args: argparse.Namespace) -> int:
    try:
        channels = [c.strip() for c in args.channels.split(",")] if args.channels else None
        for name in channels or ():
            if name not in RIDER_INDEX and name not in RIDER_PART_NAMES:
                raise FrameFileError("--channels", f"unknown rider channel {name!r}")
        animator = AnimatorLayer.load(args.offsets) if args.offsets else AnimatorLayer()
        params = load_preset(args.preset)
        started = time.perf_counter()
        take = _streamable(args, channels)
        if take is not None:
            scale = _scale_of(args, take)
            timings = _bake_streamed(args, take, RiderModel(params=params, scale=scale, animator=animator), started)
            if args.timings:
                print(f"riderlive bake: {timings}", file=sys.stderr)
            return 0
        table = read_frames(args.input, fmt=args.format)
        read = time.perf_counter()
        saddle = None
        from riderlive.saddle.estimator import Model
        from riderlive.saddle.takes import horse_take, is_saddle_take, point_of, saddle_take

        point = point_of(args)  # the live service's saddle point (--config's [saddle], --forward, --up)
        if is_saddle_take(table):  # a rider from the saddle alone (docs/saddle.md): metres in
            saddle, scale = FrameTable(table.names, table.values, table.t), RIG_UNITS_PER_METRE
            table, _ = horse_take(table, Model(point=point), rate=args.rate)
            if args.scale is not None:
                scale = args.scale
        else:
            missing = [name for name in RULE_INPUTS if name not in table.names]
            if missing:
                raise FrameFileError(args.input, f"missing required channel(s): {', '.join(missing)}", line=1)
            scale, warning = resolve_scale(args.input, table, args.scale)
            if warning:
                print(f"riderlive bake: warning: {warning}", file=sys.stderr)
        model = RiderModel(params=params, scale=scale, animator=animator)
        result = bake_table(table, model, channels, rate=args.rate)
        rules = time.perf_counter()
        if args.saddle:
            columns = saddle_take(table, point, metres_per_unit(scale)) if saddle is None else _saddle_columns(saddle)
            result = with_saddle(result, columns)
        _write_with_progress(args.output, result, args.format)
        timings = Timings(len(table), read - started, rules - read, time.perf_counter() - rules)
    except (FrameFileError, ConfigError, ValueError) as exc:
        print(f"riderlive bake: {exc}", file=sys.stderr)
        return 2
    if args.timings:
        print(f"riderlive bake: {timings}", file=sys.stderr)
    return 0


def _streamable(args: argparse.Namespace, channels: Sequence[str] | None) -> ParquetTake | None:
    """The input as a horse take to stream (Parquet file to Parquet file, rider channels only), or None."""
    if "-" in (args.input, args.output) or args.saddle or any(n in RIDER_PART_NAMES for n in channels or ()):
        return None
    if file_format(args.input, args.format) != "parquet" or file_format(args.output, args.format) != "parquet":
        return None
    from riderlive.saddle.takes import is_saddle_take

    take = open_parquet(args.input)
    if is_saddle_take(FrameTable(take.channels, np.empty((0, len(take.channels))))):
        return None  # the horse is rebuilt from the whole saddle take
    missing = [name for name in RULE_INPUTS if name not in take.names]
    if missing:
        raise FrameFileError(args.input, f"missing required channel(s): {', '.join(missing)}", line=1)
    return take


def _scale_of(args: argparse.Namespace, take: ParquetTake) -> float:
    """As :func:`resolve_scale` (which reads the hoof heights only when nothing else says)."""
    unrecorded = args.scale is None and recorded_scale(args.input) is None
    evidence = read_columns(take, HOOF_HEIGHTS) if unrecorded else FrameTable((), np.empty((0, 0)))
    scale, warning = resolve_scale(args.input, evidence, args.scale)
    if warning:
        print(f"riderlive bake: warning: {warning}", file=sys.stderr)
    return scale


def _bake_streamed(args: argparse.Namespace, take: ParquetTake, model: RiderModel, started: float) -> Timings:
    """Stream ``take`` through the rules into ``args.output``; the time spent in each stage."""
    from riderlive import fastpath

    names = [c.strip() for c in args.channels.split(",")] if args.channels else list(RIDER_NAMES)
    compiled = fastpath.AVAILABLE and take.frames >= COMPILED_FROM
    filters = Filters(model)
    reading = _Stage(read_chunks(take))
    rules = _Stage(bake_chunks(reading, model, names, args.rate, compiled, filters))
    opened = time.perf_counter()
    with _progress(take.frames) as bar:
        write_chunks(args.output, ["t", *names], rules, progress=bar)
    total = time.perf_counter() - opened
    # the rules stage pulls the read stage through: its time holds the reading's
    return Timings(
        take.frames,
        opened - started + reading.seconds,
        rules.seconds - reading.seconds,
        total - rules.seconds,
        smoothing=filters.seconds,
    )


T = TypeVar("T")


class _Stage(Iterator[T]):
    """An iterator that adds up the seconds spent producing its items."""

    def __init__(self, items: Iterable[T]) -> None:
        self.items, self.seconds = iter(items), 0.0

    def __next__(self) -> T:
        begin = time.perf_counter()
        try:
            return next(self.items)
        finally:
            self.seconds += time.perf_counter() - begin


@contextmanager
def _progress(frames: int) -> Iterator[Callable[[int], object] | None]:
    """A progress bar's update on a terminal for a long take, else None."""
    if not sys.stderr.isatty() or frames < 100_000:
        yield None
        return
    from tqdm import tqdm

    with tqdm(total=frames, unit="frames", unit_scale=True, desc="baking", file=sys.stderr) as bar:
        yield bar.update


def _saddle_columns(table: FrameTable) -> FrameTable:
    from riderlive.channels import SADDLE_NAMES

    return FrameTable(SADDLE_NAMES, table.values[:, [table.names.index(n) for n in SADDLE_NAMES]], table.t)


def _write_with_progress(path: str, table: FrameTable, fmt: str | None) -> None:
    if not sys.stderr.isatty() or len(table) < 100_000:
        write_frames(path, table, fmt)
        return
    from tqdm import tqdm

    with tqdm(total=len(table), unit="frames", unit_scale=True, desc="writing", file=sys.stderr) as bar:
        write_frames(path, table, fmt, progress=bar.update)
