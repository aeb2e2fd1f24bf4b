"""Whole takes: horse take -> saddle take, saddle take -> horse take (for ``bake`` and ``riderlive saddle``).

A saddle take is a frame file with the six ``channels.SADDLE`` columns (metres and
degrees, the saddle point's motion; see :mod:`riderlive.saddle.pose`) and ideally a
``t`` column; a horse take has the horse channels. Rows must be in time order; a
take without ``t`` is taken at ``rate`` Hz.

The saddle point of the offline commands (``bake``, ``platform``, ``saddle``) is the live
service's: ``--config SERVICE.toml`` reads its ``[saddle]`` section, ``--forward`` /
``--up`` override it (:func:`add_point_arguments`, :func:`point_of`).
"""

from __future__ import annotations

import argparse
from typing import Any

from riderlive.channels import HORSE_NAMES, SADDLE_NAMES
from riderlive.configfile import read_toml, validate
from riderlive.framefile import FrameTable, horse_matrix
from riderlive.saddle.estimator import Model
from riderlive.saddle.pose import SaddlePoint, saddle_matrix
from riderlive.saddle.rebuild import Rebuilt, rebuild
from riderlive.units import horse_lengths


def is_saddle_take(table: FrameTable) -> bool:
    """Whether ``table`` carries the saddle's six channels and no horse channel."""
    names = set(table.names)
    return names.issuperset(SADDLE_NAMES) and not names.intersection(HORSE_NAMES)


def saddle_take(horse: FrameTable, point: SaddlePoint | None = None, metres_per_unit: float = 1.0) -> FrameTable:
    """The saddle (m, deg) of every frame of a horse take whose lengths are ``metres_per_unit`` m
    each (horse channels it lacks count as 0)."""
    frames = horse_lengths(metres_per_unit).rows_to_metres(horse_matrix(horse))
    return FrameTable(SADDLE_NAMES, saddle_matrix(frames, point), horse.t)


def horse_take(saddle: FrameTable, model: Model | None = None, rate: float = 120.0) -> tuple[FrameTable, Rebuilt]:
    """The horse the estimator rebuilds from a saddle take, frame for frame, and the run's estimates."""
    model = model or Model()
    missing = [n for n in SADDLE_NAMES if n not in saddle.names]
    if missing:
        raise ValueError(f"a saddle take needs {', '.join(missing)}")
    times = saddle.times(rate)
    values = saddle.values[:, [saddle.names.index(n) for n in SADDLE_NAMES]]
    run = rebuild(model, times, values)
    return FrameTable(HORSE_NAMES, run.horse, saddle.t), run


def add_point_arguments(parser: argparse.ArgumentParser) -> None:
    """``--config``, ``--forward``, ``--up``: the saddle point (see the module docstring)."""
    parser.add_argument("--config", help="service configuration (TOML): its [saddle] point, as the live service")
    parser.add_argument("--forward", type=float, help=f"saddle point: m ahead of the hips ({SaddlePoint().forward})")
    parser.add_argument("--up", type=float, help=f"saddle point: m above the hips ({SaddlePoint().up})")


def point_of(args: argparse.Namespace) -> SaddlePoint:
    """The saddle point of :func:`add_point_arguments` (ConfigError naming the file or flag and key)."""
    section: Any = {}
    source = "saddle point (--forward, --up)"
    if args.config:
        data = read_toml(args.config)
        section = data.get("saddle", {})
        if not isinstance(section, dict):
            section = {"": section}
        source = f"{args.config} [saddle]"
        validate(SaddlePoint, section, source)
    flags = {k: v for k, v in (("forward", args.forward), ("up", args.up)) if v is not None}
    if flags:
        source = f"{source} with --forward, --up" if args.config else source
    return validate(SaddlePoint, {**section, **flags}, source)
