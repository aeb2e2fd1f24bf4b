"""Commands from the web process to the tick process (pickled over a pipe)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from riderlive.horse.terrain import TerrainConfig
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
class SetTerrain:
    """Change the ground under the procedural horse from now (None: flat and level); the
    ground under it stays and the slope eases into the new one (``horse.terrain.join``)."""

    terrain: TerrainConfig | None


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
    """Wake the tick: an e-stop was just recorded in the latch (the latch is what counts;
    this only ends the tick's sleep early)."""


@dataclass(frozen=True)
class Arm:
    """An operator arms ``device`` (its name is the confirmation). Replied to."""

    device: str
    by: str
    request: int = 0


@dataclass(frozen=True)
class Disarm:
    """Ease ``device`` (every device when None) to park, then outputs off. Replied to."""

    device: str | None = None
    by: str = "operator"
    request: int = 0


@dataclass(frozen=True)
class Reset:
    """Clear the e-stop latch and e-stops/faults of ``device`` (all when None): to
    ``disarmed``; never arms. Replied to when ``request`` is set."""

    device: str | None = None
    by: str = "operator"
    request: int = 0


@dataclass(frozen=True)
class Reload:
    """Re-read ``device``'s configuration file and connect it again (refused while it moves)."""

    device: str
    by: str = "operator"
    request: int = 0


@dataclass(frozen=True)
class Tune:
    """Live cueing parameters of the platform ``device`` (intensity, cut-offs; validated by the
    tick against the whole set); the running cue blends toward them. Replied to."""

    device: str
    changes: dict[str, Any]
    by: str = "operator"
    request: int = 0


@dataclass(frozen=True)
class Stop:
    """Park the devices, then end the tick process."""


@dataclass(frozen=True)
class Reply:
    """The tick's answer to a request (tick -> web, same pipe)."""

    request: int
    ok: bool
    states: dict[str, str]
    """Device name -> its state after the request."""
    refusal: str | None = None
    """A ``devices.lifecycle.Refusal`` value when refused."""
    message: str = ""


Command = (
    SetMode
    | SetGait
    | SetTerrain
    | Perform
    | SetModel
    | ProducerGone
    | EStop
    | Arm
    | Disarm
    | Reset
    | Reload
    | Tune
    | Stop
)
Request = Arm | Disarm | Reset | Reload | Tune
