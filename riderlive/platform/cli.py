"""``riderlive platform``: bake a take to actuator tracks, plot them, describe a platform.

::

    riderlive platform stewart_linear --info
    riderlive platform stewart_linear take.csv -o tracks.csv --plot tracks.png
    riderlive platform heave_pitch_roll saddle.csv --preset gentle --intensity 80 -o tracks.csv

The input is a frame file of saddle frames (``saddle.tx ty tz rx ry rz``, m and deg) or
horse frames, turned into the saddle pose first at the live service's saddle point
(``--config SERVICE.toml``: its ``[saddle]``; ``--forward``/``--up``), lengths in the
unit recorded beside the take (``NAME.json``) or ``--scale``, else metres. The output has ``t``, the platform's pose
relative to home (``platform.tx`` ... ``platform.rz``, after the workspace scale-back)
and one column per actuator (``platform.a1`` ...: m of extension or deg of crank),
after the safety stage. Bad input exits with status 2 and a message; nothing is written.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from riderlive.configfile import ConfigError
from riderlive.framefile import DEFAULT_RATE, FrameFileError, FrameTable, read_frames, write_frames
from riderlive.frameunits import METRES, recorded_scale
from riderlive.platform.mechanism.config import PlatformConfig, load_platform
from riderlive.platform.mechanism.geometry import POSE_AXES
from riderlive.platform.mechanism.ik import axis_ranges
from riderlive.platform.mechanism.pipeline import Bake, PlatformModel, bake
from riderlive.platform.saddle_input import saddle_pose
from riderlive.saddle.takes import add_point_arguments, point_of
from riderlive.units import metres_per_unit


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("platform", help="platform file, or a shipped platform's name (config/platforms)")
    parser.add_argument("input", nargs="?", help="take: saddle or horse frames (.csv, .jsonl, or -)")
    parser.add_argument("-o", "--output", help="actuator tracks to write (.csv, .jsonl, or -)")
    parser.add_argument("--plot", help="PNG of the saddle, the platform's pose and the actuators")
    parser.add_argument("--info", action="store_true", help="print the platform's geometry and reach")
    parser.add_argument("--preset", help="cueing preset (gentle, standard, lively)")
    parser.add_argument("--intensity", type=float, help="cueing intensity, 0-100 %%")
    parser.add_argument("--rate", type=float, default=DEFAULT_RATE, help="Hz, for input without a t column")
    parser.add_argument("--format", choices=("csv", "jsonl"), help="format for - (default csv)")
    parser.add_argument(
        "--scale",
        type=float,
        help="horse frames: thesis rig units per length unit (25: metres); default: NAME.json, else metres",
    )
    add_point_arguments(parser)


def describe(cfg: PlatformConfig, model: PlatformModel) -> str:
    """A human summary: what it is, actuators, home/park positions, reach and cue scale per axis."""
    g = model.geometry
    unit = g.unit
    lines = [
        f"{cfg.name}: {cfg.description}",
        f"kind {g.kind.value}, carries a {cfg.carries} ({cfg.payload_kg:g} kg), {g.legs} actuators",
        f"soft range {g.lower[0]:.4g} .. {g.upper[0]:.4g} {unit}, max speed {max(g.max_speed):g} {unit}/s, "
        f"max accel {max(g.max_accel):g} {unit}/s^2",
        "home positions " + " ".join(f"{q:.4g}" for q in model.home_positions) + f" {unit}",
        "park positions " + " ".join(f"{q:.4g}" for q in model.park_positions) + f" {unit}",
        f"cueing preset {cfg.cueing.preset}, intensity {cfg.cueing.intensity:g} %",
        "axis  reach from home, each axis alone   cue scale",
    ]
    scales = model.cueing.scales
    for name, (down, up), scale in zip(POSE_AXES, axis_ranges(g), scales, strict=True):
        u = "m" if name.startswith("t") else "deg"
        reach = f"-{down:.4g} / +{up:.4g} {u}" if max(down, up) > 0.0 else "(held by the mechanism)"
        lines.append(f"{name:4}  {reach:34} {scale:.3g}")
    return "\n".join(lines)


def tracks_table(model: PlatformModel, result: Bake, times: np.ndarray) -> FrameTable:
    """The pose relative to home (``platform.tx`` ...) and the commands (``platform.a1`` ...)."""
    legs = result.positions.shape[1]
    names = tuple(f"platform.{a}" for a in POSE_AXES) + tuple(f"platform.a{i + 1}" for i in range(legs))
    values = np.column_stack([result.pose - np.asarray(model.geometry.home), result.positions])
    return FrameTable(names, values, times)


def plot_tracks(model: PlatformModel, saddle: np.ndarray, times: np.ndarray, result: Bake, title: str) -> Any:
    """Saddle (dashed) and platform pose (solid) per axis, and the actuators within their soft range."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = model.geometry
    home = np.asarray(g.home)
    pose = result.pose - home
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(10, 7), dpi=72)
    colours = ("#1f77b4", "#2ca02c", "#d62728")
    for panel, (first, unit) in zip(axes[:2], ((0, "m"), (3, "deg")), strict=True):
        for j in range(3):
            axis = first + j
            if not g.kind.axes[axis] and axis not in (3, 5):
                continue
            name = POSE_AXES[axis]
            panel.plot(times, saddle[:, axis], "--", lw=0.8, color=colours[j], label=f"saddle.{name}")
            panel.plot(times, pose[:, axis], lw=1.4, color=colours[j], label=f"platform.{name}")
        panel.set_ylabel(unit)
        panel.legend(loc="upper right", fontsize=8, ncol=3)
        panel.grid(alpha=0.3)
    lo, hi = np.asarray(g.lower), np.asarray(g.upper)
    share = (result.positions - lo) / (hi - lo)
    ax = axes[2]
    for i in range(g.legs):
        ax.plot(times, share[:, i], lw=1.0, label=f"a{i + 1}")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axhline(1.0, color="k", lw=0.8)
    scaled = result.scale < 1.0
    if scaled.any():
        ax.fill_between(times, -0.05, 1.05, where=scaled, color="orange", alpha=0.2, label="scaled back")
    ax.set_ylabel("actuators (share of soft range)")
    ax.set_xlabel("s")
    ax.legend(loc="upper right", fontsize=8, ncol=7)
    ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def run(args: argparse.Namespace) -> int:
    try:
        cfg = load_platform(args.platform)
        changes: dict[str, Any] = {}
        if args.intensity is not None:
            changes["intensity"] = args.intensity
        model = PlatformModel.from_config(cfg)
        if args.preset or changes:
            model = replace(model, cueing=model.cueing.with_preset(args.preset or cfg.cueing.preset, **changes))
        if args.info:
            print(describe(cfg, model))
        if args.input is None:
            if not args.info:
                raise ValueError("give a take to bake (and -o and/or --plot), or --info")
            return 0
        if not (args.output or args.plot):
            raise ValueError("give -o FILE and/or --plot PNG")
        if not (1.0 <= args.rate <= 10000.0):
            raise ValueError(f"--rate must be within 1-10000 Hz, got {args.rate}")
        table = read_frames(args.input, fmt=args.format)
        times = table.times(args.rate)
        if len(table) < 2:
            raise FrameFileError(args.input, "a take needs at least two frames")
        dt = np.diff(times, prepend=times[0] - (times[1] - times[0]))
        scale = args.scale if args.scale is not None else recorded_scale(args.input) or METRES
        saddle = saddle_pose(table, args.input, point_of(args), metres_per_unit(scale))
        result = bake(model, saddle, dt)
        if args.output:
            write_frames(args.output, tracks_table(model, result, times), args.format)
        if args.plot:
            fig = plot_tracks(model, saddle, times, result, f"{cfg.name}: {Path(args.input).name}")
            fig.savefig(args.plot)
        counters = result.state.counters
        print(
            f"{len(table)} frames; scaled back {counters['scaled_back_frames']}, speed-limited "
            f"{counters['speed_limited_frames']}, accel-limited {counters['accel_limited_frames']}, "
            f"soft-limit {counters['soft_limit_frames']}",
            file=sys.stderr,
        )
    except (ConfigError, FrameFileError, ValueError) as exc:
        print(f"riderlive platform: {exc}", file=sys.stderr)
        return 2
    return 0
