"""``riderlive horse``: write a procedural take (a gait, a shot script or an aid script) to a frame file."""

from __future__ import annotations

import argparse
import sys

from riderlive.configfile import ConfigError
from riderlive.framefile import FORMATS, FrameFileError, write_frames
from riderlive.frameunits import METRES, record_scale
from riderlive.horse.aids import load_take
from riderlive.horse.gaits import GAITS
from riderlive.horse.script import ShotScript, gait_script, generate


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--gait", choices=(*GAITS, "halt"), help="hold one gait")
    source.add_argument("--script", help="shot script (TOML) of gait and move segments, or of the rider's aids")
    parser.add_argument("--seconds", type=float, default=10.0, help="length of a --gait take (default 10)")
    parser.add_argument("--speed", type=float, help="m/s for --gait (default: the gait's)")
    parser.add_argument("--rate", type=float, default=120.0, help="frames per second (default 120)")
    parser.add_argument("--seed", type=int, help="turn on seeded stride-to-stride variation")
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        help="frame file to write (.csv, .jsonl, .parquet, or -); metres, recorded in NAME.json",
    )
    parser.add_argument("--format", choices=FORMATS, help="format for - (default csv)")


def run(args: argparse.Namespace) -> int:
    try:
        if not (30.0 <= args.rate <= 1000.0):
            raise ValueError(f"--rate must be within 30-1000 Hz, got {args.rate}")
        script: ShotScript
        if args.script:
            script = load_take(args.script)
            if args.seed is not None:
                script = script.model_copy(update={"seed": args.seed})
        else:
            script = gait_script(args.gait, args.seconds, args.speed, args.seed)
        write_frames(args.output, generate(script, args.rate), args.format)
        record_scale(args.output, METRES, source="riderlive horse", rate=args.rate)
    except (ConfigError, FrameFileError, ValueError) as exc:
        print(f"riderlive horse: {exc}", file=sys.stderr)
        return 2
    return 0
