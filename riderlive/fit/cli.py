"""``riderlive fit HORSE RIDER [HORSE2 RIDER2 ...] -o my_rider.toml``: a preset from takes (docs/fit.md).

Exit status 0 with the preset written; 2 when the takes cannot be used or identify nothing
(the message says which and why; no preset is written then).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import orjson

from riderlive.configfile import ConfigError
from riderlive.fit.offset import SEARCH
from riderlive.fit.problem import FitInputError, TakePair
from riderlive.framefile import FrameFileError, atomic_path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "takes",
        nargs="+",
        metavar="HORSE RIDER",
        help="pairs of takes: a horse take (.csv, .jsonl, .parquet; as bake reads) and the rider recorded with it "
        "(.csv, .jsonl, .parquet of rider channels, or .bvh through --bonemap)",
    )
    parser.add_argument("-o", "--output", required=True, help="preset TOML to write")
    parser.add_argument(
        "--from", dest="start", default="kuhnel2003", help="starting preset, name or path (default kuhnel2003)"
    )
    parser.add_argument("--report", help="also write the report as JSON here")
    parser.add_argument("--plot", help="PNG of the first take: rider, fitted and starting prediction")
    parser.add_argument(
        "--bonemap", help="bone map of the BVH riders: a name in config/bonemaps (default riderlive) or a .toml path"
    )
    parser.add_argument(
        "--drift", action="store_true", help="take out each take's translation offsets and trends (mocap drift)"
    )
    parser.add_argument(
        "--search", type=float, default=SEARCH, help=f"largest clock offset searched, s (default {SEARCH}; 0: none)"
    )
    parser.add_argument("--scale", type=float, help="thesis rig units per horse length unit (as bake --scale)")
    parser.add_argument("--rate", type=float, default=120.0, help="Hz of takes without a t column (default 120)")
    parser.add_argument("--quiet", action="store_true", help="print no report")


def run(args: argparse.Namespace) -> int:
    from riderlive.fit import presetfile, report
    from riderlive.fit.solve import FitOptions, fit
    from riderlive.fit.takes import read_horse, read_rider
    from riderlive.rules.params import load_preset

    try:
        if len(args.takes) % 2:
            raise FitInputError(f"takes come in pairs (HORSE RIDER), got {len(args.takes)} file(s)")
        if not 0.0 <= args.search <= 0.5:
            raise FitInputError(f"--search must be within 0-0.5 s, got {args.search}")
        start = load_preset(args.start)
        pairs, notes = [], []
        for horse_path, rider_path in zip(args.takes[::2], args.takes[1::2], strict=True):
            horse, horse_notes = read_horse(horse_path, args.scale, args.rate)
            rider, rider_notes = read_rider(rider_path, horse.scale, args.rate, args.bonemap)
            pairs.append(TakePair(horse, rider))
            notes += horse_notes + rider_notes
        solution = fit(pairs, start, FitOptions(drift=args.drift, search=args.search))
        data = report.build(solution, notes)
        presetfile.write(args.output, solution.preset, data)
        if args.report:
            with atomic_path(args.report) as tmp:
                tmp.write_bytes(orjson.dumps(data, option=orjson.OPT_INDENT_2 | orjson.OPT_SERIALIZE_NUMPY))
        if args.plot:
            report.plot(solution, args.plot)
    except (FitInputError, FrameFileError, ConfigError, ValueError, OSError) as exc:
        print(f"riderlive fit: {exc}", file=sys.stderr)
        return 2
    if not args.quiet:
        print(report.text(data))
        print(f"\nwrote {Path(args.output)}")
    return 0
