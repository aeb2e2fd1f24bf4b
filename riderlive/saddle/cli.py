"""``riderlive saddle``: the saddle pose of a horse take or a procedural horse, or a horse rebuilt from a saddle.

    riderlive saddle horse.csv -o saddle.csv                 # a horse take's saddle
    riderlive saddle --gait trot --seconds 20 -o saddle.csv  # the procedural horse's (or --script)
    riderlive saddle --gait canter --imu-strap --seed 3 -o rec.csv   # a realistic synthetic recording
    riderlive saddle --rebuild rec.csv -o horse.csv          # the horse the estimator sees in a saddle take

A synthetic recording can be spoiled like a sensor: ``--drift`` (m/s), ``--yaw-drift``
(deg/s), ``--tilt`` (deg), ``--noise`` (m), ``--angle-noise`` (deg), ``--dropout``
(fraction), or ``--imu-strap`` for the issue's case (2 cm/s, 5 mm, 10 %).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter

from riderlive.configfile import ConfigError
from riderlive.framefile import FrameFileError, FrameTable, read_frames, write_frames
from riderlive.horse.gaits import GAITS
from riderlive.horse.script import ShotScript, gait_script, load_script
from riderlive.saddle.estimate import estimate
from riderlive.saddle.estimator import Model
from riderlive.saddle.synthetic import IMU_STRAP, Imperfections, record
from riderlive.saddle.takes import add_point_arguments, horse_take, point_of, saddle_take


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("input", nargs="?", help="horse take (.csv, .jsonl or -): write its saddle")
    source.add_argument("--gait", choices=(*GAITS, "halt"), help="the procedural horse holding one gait")
    source.add_argument("--script", help="the procedural horse playing a shot script (TOML)")
    source.add_argument("--rebuild", metavar="SADDLE", help="saddle take: write the horse the estimator rebuilds")
    parser.add_argument("-o", "--output", required=True, help="file to write (.csv, .jsonl, or -)")
    parser.add_argument("--format", choices=("csv", "jsonl"), help="format for - (default csv)")
    add_point_arguments(parser)
    procedural = parser.add_argument_group("procedural horse")
    procedural.add_argument("--seconds", type=float, default=10.0, help="length of a --gait take (default 10)")
    procedural.add_argument("--speed", type=float, help="m/s for --gait (default: the gait's)")
    procedural.add_argument("--rate", type=float, default=120.0, help="frames per second, 10-1000 (default 120)")
    procedural.add_argument("--start", type=float, default=0.0, help="start this many seconds in (mid-stride)")
    procedural.add_argument("--seed", type=int, help="stride-to-stride variation and the sensor's faults, seeded")
    faults = parser.add_argument_group("a sensor's faults (procedural horse only)")
    faults.add_argument("--imu-strap", action="store_true", help="2 cm/s drift, 5 mm noise, 10 %% dropped, and more")
    faults.add_argument("--drift", type=float, default=0.0, help="translation drift, m/s")
    faults.add_argument("--yaw-drift", type=float, default=0.0, help="heading drift, deg/s")
    faults.add_argument("--tilt", type=float, default=0.0, help="pitch and roll offset, deg")
    faults.add_argument("--noise", type=float, default=0.0, help="translation noise (standard deviation), m")
    faults.add_argument("--angle-noise", type=float, default=0.0, help="rotation noise (standard deviation), deg")
    faults.add_argument("--dropout", type=float, default=0.0, help="fraction of frames lost, 0-1")


def _script(args: argparse.Namespace) -> ShotScript:
    if args.script:
        script = load_script(args.script)
        return script.model_copy(update={"seed": args.seed}) if args.seed is not None else script
    return gait_script(args.gait, args.seconds, args.speed, args.seed)


def _faults(args: argparse.Namespace) -> Imperfections:
    if args.imu_strap:
        return IMU_STRAP
    return Imperfections(args.drift, args.yaw_drift, args.tilt, args.noise, args.angle_noise, args.dropout)


def _summary(run_estimates: Counter[str], final: dict[str, int]) -> str:
    locks = ", ".join(f"{name} {count}" for name, count in run_estimates.most_common())
    odd = ", ".join(f"{name} {count}" for name, count in final.items() if count and name != "samples")
    return f"riderlive saddle: frames by state: {locks}; counters: {odd}"


def run(args: argparse.Namespace) -> int:
    try:
        point = point_of(args)
        table: FrameTable
        if args.rebuild:
            table, run_ = horse_take(read_frames(args.rebuild, fmt=args.format), Model(point=point))
            states = Counter(
                f"{lock}:{gait}" if gait else lock for lock, gait in zip(run_.lock, run_.gait, strict=True)
            )
            print(_summary(states, estimate(run_.final).counters), file=sys.stderr)
        elif args.input:
            table = saddle_take(read_frames(args.input, fmt=args.format), point)
        else:
            recording = record(
                _script(args),
                args.rate,
                start=args.start,
                imperfections=_faults(args),
                seed=args.seed or 0,
                point=point,
            )
            table = recording.saddle
        write_frames(args.output, table, args.format)
    except (ConfigError, FrameFileError, ValueError) as exc:
        print(f"riderlive saddle: {exc}", file=sys.stderr)
        return 2
    return 0
