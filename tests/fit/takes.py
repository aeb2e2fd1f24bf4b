"""Procedural horse takes and their riders baked by a known preset: the fit's ground truth."""

from __future__ import annotations

from functools import cache

import numpy as np

from riderlive.bake import bake_table
from riderlive.channels import RIDER_NAMES
from riderlive.configfile import CONFIG_DIR
from riderlive.fit.problem import HORSE_READ, HorseTake, RiderTake, TakePair
from riderlive.framefile import FrameTable
from riderlive.horse import DEFAULT_SCALE, generate, load_script
from riderlive.horse.script import gait_script
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams

RATE = 120.0


@cache
def horse_table(what: str, seconds: float = 8.0) -> FrameTable:
    """A procedural horse take in metres: a gait for ``seconds``, or a shot script of config/shots."""
    if what in ("walk", "trot", "canter", "gallop"):
        return generate(gait_script(what, seconds, None, 7), RATE)
    return generate(load_script(CONFIG_DIR / "shots" / f"{what}.toml"), RATE)


def horse_take(what: str, seconds: float = 8.0) -> HorseTake:
    table = horse_table(what, seconds)
    t = table.times(RATE)
    columns = {n: table.column(n) for n in HORSE_READ if n in table.names}
    return HorseTake(what, t, columns, DEFAULT_SCALE)


def rider_table(what: str, preset: RuleParams, seconds: float = 8.0) -> FrameTable:
    return bake_table(horse_table(what, seconds), RiderModel(params=preset, scale=DEFAULT_SCALE), rate=RATE)


def pair(what: str, preset: RuleParams, seconds: float = 8.0, names: tuple[str, ...] = RIDER_NAMES) -> TakePair:
    rider = rider_table(what, preset, seconds)
    values = np.column_stack([rider.column(n) for n in names])
    return TakePair(horse_take(what, seconds), RiderTake(f"{what} rider", rider.times(RATE), names, values))
