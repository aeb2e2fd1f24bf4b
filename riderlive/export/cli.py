"""``riderlive export TAKE --format bvh|gltf|mcap``: a take as files engines, Blender and Foxglove import.

Every file carries the take's start timecode when it has one (docs/timecode.md): glTF in
``asset.extras.riderlive``, MCAP in its ``riderlive`` metadata and every joints message,
BVH (which has no comment syntax importers agree on) in ``STEM.timecode.json`` beside
the ``.bvh`` files. A file is written whole or not at all.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import orjson

from riderlive.export.take import ExportError, load_take, resolve_take, sidecar_of, timecode_fields
from riderlive.framefile import _atomic_binary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("take", help="a take name (in --takes) or a frame file path")
    parser.add_argument(
        "--format", choices=("bvh", "gltf", "mcap"), required=True, help="BVH (one file per skeleton), .glb or .mcap"
    )
    parser.add_argument(
        "-o",
        "--output",
        help="output file (.glb, .mcap) or BVH stem (STEM.rider.bvh, STEM.horse.bvh); default: the take's name",
    )
    parser.add_argument("--takes", default="takes", help="takes directory (default: takes)")
    parser.add_argument("--unit", choices=("m", "cm"), default="m", help="BVH length unit (glTF is always metres)")
    parser.add_argument("--length-scale", type=float, help="thesis units per take length unit (default: sidecar or 25)")
    parser.add_argument("--rate", type=float, help="frames per second (default: the take's tick rate)")


def outputs(take_name: str, output: str | None, fmt: str, skeletons: list[str]) -> dict[str, Path]:
    """Skeleton (or ``all``) -> output path."""
    if fmt in ("gltf", "mcap"):
        suffix = ".glb" if fmt == "gltf" else ".mcap"
        path = Path(output or f"{take_name}{suffix}")
        return {"all": path if path.suffix else path.with_suffix(suffix)}
    stem = output or take_name
    stem = stem[:-4] if stem.endswith(".bvh") else stem
    return {name: Path(f"{stem}.{name}.bvh") for name in skeletons}


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    try:
        path = resolve_take(args.take, args.takes)
        if args.rate is not None and not 1.0 <= args.rate <= 1000.0:
            raise ExportError("--rate must be 1..1000 frames per second")
        take = load_take(path, args.length_scale, args.rate)
    except ExportError as exc:
        print(f"riderlive export: {exc}", file=sys.stderr)
        return 2
    tracks = {t.rig.name: t for t in (take.horse, take.rider) if t is not None}
    targets = outputs(take.name, args.output, args.format, list(tracks))
    for target in targets.values():
        if not target.parent.is_dir():
            print(f"riderlive export: {target.parent}: no such directory", file=sys.stderr)
            return 2
    if args.format == "gltf":
        from riderlive.export.gltf import write_glb

        with _atomic_binary(str(targets["all"])) as fh:
            write_glb(fh, take)
    elif args.format == "mcap":
        from riderlive.export.mcap import start_ns, write_mcap

        with _atomic_binary(str(targets["all"])) as fh:
            write_mcap(fh, take, start_ns(sidecar_of(path).get("started")))
    else:
        from riderlive.export.bvh import write_bvh

        for name, target in targets.items():
            with _atomic_binary(str(target)) as fh:
                write_bvh(fh, tracks[name], take.rate, args.unit)
        stamp = timecode_fields(take)
        if stamp:
            stem = next(iter(targets.values())).with_suffix("").with_suffix("")
            with _atomic_binary(f"{stem}.timecode.json") as fh:
                fh.write(orjson.dumps({**stamp, "rate": take.rate, "files": [t.name for t in targets.values()]}))
    seconds = time.perf_counter() - start
    note = f"; ignored {len(take.ignored)} channels that pose no bone" if take.ignored else ""
    print(
        f"riderlive export: {len(take.t)} frames at {take.rate:g} Hz ({', '.join(tracks)}) -> "
        f"{', '.join(map(str, targets.values()))} in {seconds:.2f} s{note}",
        file=sys.stderr,
    )
    return 0
