"""``riderlive tail FILE -o OUT``: the skinned tail and braid (and optionally the reference) on a horse take.

The take's horse channels (metres, degrees; omitted channels are zero) drive the
strands; the rider rules pose the rider for the braid. The physics steps at the
configured fixed rate whatever the take's frame rate; one output frame is written per
input frame, at the same times.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

import numpy as np

from riderlive.configfile import ConfigError
from riderlive.framefile import (
    DEFAULT_RATE,
    FORMATS,
    FrameFileError,
    FrameTable,
    horse_matrix,
    read_frames,
    write_frames,
)
from riderlive.frameunits import recorded_scale, rescale_lengths
from riderlive.horse import DEFAULT_SCALE
from riderlive.physics.config import PhysicsConfig, load_physics
from riderlive.physics.drive import FixedStepper, TakeSource
from riderlive.physics.outputs import channel_names, publish
from riderlive.physics.reference import ReferenceModel, mean_tip
from riderlive.physics.skinned import SkinnedModel
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from riderlive.units import metres_per_unit

REFERENCE_CHANNELS = ("tail_ref.tx", "tail_ref.ty", "tail_ref.tz")
"""The reference tail's mean tip position, world metres (with ``--reference``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="horse take: .csv, .jsonl or .parquet (metres, degrees), or - for stdin")
    parser.add_argument("-o", "--output", required=True, help="bone channels to write (.csv, .jsonl, .parquet, -)")
    parser.add_argument("--config", help="physics TOML (default config/physics/tail.toml)")
    parser.add_argument("--preset", default="kuhnel2003", help="rider rules preset for the braid (default kuhnel2003)")
    parser.add_argument("--no-rider", action="store_true", help="no rider rules: the braid hangs from an upright rider")
    parser.add_argument("--reference", action="store_true", help="also run the many-strand tail; adds tail_ref.t*")
    parser.add_argument("--strands", metavar="NPZ", help="with --reference: write every strand vertex per frame here")
    parser.add_argument("--rate", type=float, default=DEFAULT_RATE, help="Hz, for input without a t column")
    parser.add_argument("--format", choices=FORMATS, help="format for - (default csv)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def run_take(
    table: FrameTable,
    config: PhysicsConfig,
    rider_rules: RiderModel | None,
    rate: float,
    reference: bool,
    *,
    say: Callable[[str], object] | None = None,
) -> tuple[FrameTable, np.ndarray | None]:
    """Run the take; returns the output table and, with ``reference``, vertices (F, V, 3, N) or None.

    ``say``: progress lines (the compile or cache load before the first frame, then the frames
    about every 2 s): the first run on a machine compiles the physics for a minute or more."""
    horse = horse_matrix(table)
    times = table.times(rate)
    if len(times) > 1 and np.any(np.diff(times) <= 0.0):
        raise FrameFileError("input", "the t column must increase strictly")
    rider = None if rider_rules is None else rider_rules.evaluate_batch(horse)
    source = TakeSource(times, horse, rider)
    skinned = SkinnedModel.build(config)
    names = channel_names(skinned)
    sk = FixedStepper(skinned.step, skinned.initial(source(times[0])), config.rate, start=float(times[0]))
    ref_model = ReferenceModel.build(config) if reference else None
    ref = (
        None
        if ref_model is None
        else FixedStepper(ref_model.step, ref_model.initial(source(times[0])), config.rate, start=float(times[0]))
    )
    rows = []
    vertices = []
    if say is not None:
        say("compiling or loading the compiled physics (numba: a first run compiles for a minute or more)…")
    started = last = time.perf_counter()
    for k, t in enumerate(times):
        sk.advance_to(float(t), source)
        if say is not None:
            now = time.perf_counter()
            if k == 0:
                say(f"physics ready in {now - started:.1f} s; {len(times):,} frames")
                last = now
            elif now - last >= 2.0:
                say(f"{k + 1:,} / {len(times):,} frames")
                last = now
        row = publish(skinned, sk.state)
        if ref is not None:
            ref.advance_to(float(t), source)
            row = np.concatenate((row, mean_tip(ref.state)))
            vertices.append(ref.state.x.astype(np.float32))
        rows.append(row)
    if reference:
        names = names + REFERENCE_CHANNELS
    return FrameTable(names, np.array(rows), times), (np.array(vertices) if reference else None)


def run(args: argparse.Namespace) -> int:
    try:
        config = load_physics(args.config)
        if args.strands and not args.reference:
            raise ValueError("--strands needs --reference")
        rules = None if args.no_rider else RiderModel(params=load_preset(args.preset), scale=DEFAULT_SCALE)
        table = read_frames(args.input, fmt=args.format)
        recorded = recorded_scale(args.input)  # the physics works in metres
        table = rescale_lengths(table, metres_per_unit(recorded)) if recorded else table
        say = None if args.quiet else (lambda line: print(f"riderlive tail: {line}", file=sys.stderr, flush=True))
        result, vertices = run_take(table, config, rules, args.rate, args.reference, say=say)
        write_frames(args.output, result, args.format)
        if args.strands and vertices is not None:
            np.savez_compressed(args.strands, t=result.times(args.rate), vertices=vertices)
    except (FrameFileError, ConfigError, ValueError) as exc:
        print(f"riderlive tail: {exc}", file=sys.stderr)
        return 2
    return 0
