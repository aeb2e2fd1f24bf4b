"""Commands from the web process to the tick process (pickled over a pipe)."""

from __future__ import annotations

from dataclasses import dataclass

from riderlive.realtime.core import Mode
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.params import RuleParams


@dataclass(frozen=True)
class SetMode:
    """Select ``input`` (live producers or a replay) or pin ``procedural``."""

    mode: Mode


@dataclass(frozen=True)
class SetGait:
    """Change the procedural horse's gait (and speed, m/s)."""

    gait: str
    speed: float | None = None


@dataclass(frozen=True)
class Perform:
    """Ask the procedural horse for a move (``jump``...), if it knows moves."""

    move: str


@dataclass(frozen=True)
class SetModel:
    """New rule parameters and animator layer; the tick blends to them over ``Timing.param_blend``."""

    params: RuleParams
    animator: AnimatorLayer


@dataclass(frozen=True)
class ProducerGone:
    """A producer disconnected (or lost the arbitration): its stream ends now."""

    producer: int


@dataclass(frozen=True)
class EStop:
    """Emergency stop: the rig goes to torque off within one tick."""


@dataclass(frozen=True)
class Reset:
    """Clear an e-stop or a rig fault and start again."""


@dataclass(frozen=True)
class Stop:
    """Park the rig, then end the tick process."""


Command = SetMode | SetGait | Perform | SetModel | ProducerGone | EStop | Reset | Stop
