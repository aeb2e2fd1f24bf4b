"""Whole takes: horse take -> saddle take, saddle take -> horse take (for ``bake`` and ``riderlive saddle``).

A saddle take is a frame file with the six ``channels.SADDLE`` columns (metres and
degrees, the saddle point's motion; see :mod:`riderlive.saddle.pose`) and ideally a
``t`` column; a horse take has the horse channels. Rows must be in time order; a
take without ``t`` is taken at ``rate`` Hz.
"""

from __future__ import annotations

from riderlive.bake import horse_matrix
from riderlive.channels import HORSE_NAMES, SADDLE_NAMES
from riderlive.framefile import FrameTable
from riderlive.saddle.estimator import Model
from riderlive.saddle.pose import SaddlePoint, saddle_matrix
from riderlive.saddle.rebuild import Rebuilt, rebuild


def is_saddle_take(table: FrameTable) -> bool:
    """Whether ``table`` carries the saddle's six channels and no horse channel."""
    names = set(table.names)
    return names.issuperset(SADDLE_NAMES) and not names.intersection(HORSE_NAMES)


def saddle_take(horse: FrameTable, point: SaddlePoint | None = None) -> FrameTable:
    """The saddle of every frame of a horse take (horse channels it lacks count as 0)."""
    return FrameTable(SADDLE_NAMES, saddle_matrix(horse_matrix(horse), point), horse.t)


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
