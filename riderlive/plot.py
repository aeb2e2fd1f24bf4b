"""``riderlive plot``: channels of a frame file over time, hoof heights with footfall bars.

Draws up to three panels sharing the time axis: hoof heights with one bar lane per
hoof where it is on the ground (when the file has hoof heights), then the requested
rotation channels (deg) and translation channels (file units). ``--bake`` evaluates
the rider rules on a horse take first, so rider channels (``lower_back.rz``,
``cog.ty``) can be plotted beside the horse's. Renders with matplotlib's Agg backend
(no display needed).
"""

from __future__ import annotations

import argparse
import io
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from riderlive.channels import RIDER_INDEX, Kind, is_known, lookup
from riderlive.configfile import ConfigError
from riderlive.framefile import FrameFileError, FrameTable, read_frames

HOOVES = (("lfHoof", "LF"), ("rfHoof", "RF"), ("lbHoof", "LB"), ("rbHoof", "RB"))
GROUND = 1e-3
"""A hoof lower than this (file units) counts as on the ground."""


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, got {text!r}") from None
    if not (100 <= w <= 4000 and 100 <= h <= 4000):
        raise argparse.ArgumentTypeError("width and height must be within 100-4000 pixels")
    return w, h


def plot_tables(
    horse: FrameTable,
    channels: Sequence[str],
    rider: FrameTable | None = None,
    *,
    title: str = "",
    size: tuple[int, int] = (900, 500),
    dpi: int = 80,
    rate: float = 120.0,
) -> Any:
    """A matplotlib Figure of ``channels`` (from ``horse`` or ``rider``) and the footfalls."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = horse.times(rate)
    tables = [horse] + ([rider] if rider is not None else [])

    def column(name: str) -> np.ndarray:
        for table in tables:
            if name in table.names:
                return table.column(name)
        raise FrameFileError("--channels", f"channel {name!r} is not in the take" + ("" if rider else " (try --bake)"))

    hooves = all(f"{h}.ty" in horse.names for h, _ in HOOVES)
    angles = [c for c in channels if lookup(c).kind is Kind.ROTATION]
    lengths = [c for c in channels if lookup(c).kind is not Kind.ROTATION]
    rows = [r for r, used in (("hooves", hooves), ("deg", angles), ("len", lengths)) if used]
    if not rows:
        raise FrameFileError("--channels", "nothing to plot: no hoof heights and no channels")
    fig, axes = plt.subplots(len(rows), 1, sharex=True, figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi, squeeze=False)
    for ax, row in zip(axes[:, 0], rows, strict=True):
        if row == "hooves":
            top = max(float(max(np.max(horse.column(f"{h}.ty")) for h, _ in HOOVES)), 0.05)
            lane = top * 0.08
            for i, (hoof, label) in enumerate(HOOVES):
                y = horse.column(f"{hoof}.ty")
                (line,) = ax.plot(t, y, lw=1.2, label=label)
                base = -(i + 1) * lane * 1.3
                ax.fill_between(t, base, base + lane, where=y <= GROUND, color=line.get_color(), step="mid", lw=0)
            ax.set_ylabel("hoof height\n(bars: on ground)")
        else:
            for name in angles if row == "deg" else lengths:
                ax.plot(t, column(name), lw=1.2, label=name)
            ax.set_ylabel("deg" if row == "deg" else "length")
            ax.axhline(0.0, color="0.7", lw=0.6)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8, ncol=4)
    axes[-1, 0].set_xlabel("t (s)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def save(fig: Any, path: Path, dpi: int) -> None:
    """Write the figure; a PNG is reduced to a 64-colour palette (a quarter of the bytes)."""
    if path.suffix.lower() != ".png":
        fig.savefig(path, dpi=dpi)
        return
    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=dpi, format="png")
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(colors=64).save(path, optimize=True)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="frame file (.csv, .jsonl or .parquet)")
    parser.add_argument(
        "--channels", default="", help="comma-separated channels to plot (horse or, with --bake, rider)"
    )
    parser.add_argument("--bake", action="store_true", help="evaluate the rider rules on the take first")
    parser.add_argument("--preset", default="kuhnel2003", help="rider preset for --bake")
    parser.add_argument(
        "--scale", type=float, help="thesis rig units per input length unit for --bake (default: as riderlive bake)"
    )
    parser.add_argument("--title", default="", help="figure title")
    parser.add_argument("--size", type=_size, default=(900, 500), help="WIDTHxHEIGHT pixels (default 900x500)")
    parser.add_argument("--dpi", type=int, default=80, help="dots per inch (default 80)")
    parser.add_argument("-o", "--output", required=True, help="image to write (.png, .svg, .pdf)")


def run(args: argparse.Namespace) -> int:
    try:
        channels = [c.strip() for c in args.channels.split(",") if c.strip()]
        for name in channels:
            if not is_known(name):
                raise FrameFileError("--channels", f"unknown channel {name!r}")
        horse = read_frames(args.input)
        rider = None
        if args.bake:
            from riderlive.bake import bake_table
            from riderlive.frameunits import resolve_scale
            from riderlive.rules import RiderModel, load_preset

            scale, warning = resolve_scale(args.input, horse, args.scale)
            if warning:
                print(f"riderlive plot: warning: {warning}", file=sys.stderr)
            model = RiderModel(params=load_preset(args.preset), scale=scale)
            wanted = [c for c in channels if c in RIDER_INDEX] or None
            rider = bake_table(horse, model, wanted)
        fig = plot_tables(horse, channels, rider, title=args.title, size=args.size, dpi=args.dpi)
        save(fig, Path(args.output), args.dpi)
    except (FrameFileError, ConfigError, ValueError) as exc:
        print(f"riderlive plot: {exc}", file=sys.stderr)
        return 2
    return 0
