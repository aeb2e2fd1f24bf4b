"""The gait table: footfall timing, speeds and trunk motion of the four gaits.

Everything here is data. A gait follows Girard's PODA support profile: every leg has
a phase offset (where in the stride its hoof is placed) and a duty factor (the
fraction of the stride its hoof is on the ground); lift-off happens at
``offset + duty``, the rest of the stride is the transfer (swing). The stride
frequency rises linearly with speed across the documented ranges (``docs/horse.md``
gives every number's source). Lengths in metres for a horse of
:data:`WITHERS_HEIGHT`, angles in degrees, frequencies in strides per second.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class Gait(enum.Enum):
    """The gaits; ``HALT`` is standing square (after a stop or a rear)."""

    WALK = "walk"
    TROT = "trot"
    CANTER = "canter"
    GALLOP = "gallop"
    HALT = "halt"


class Leg(enum.IntEnum):
    """The four legs, in the order of the hoof channels of ``channels.HORSE``."""

    LF = 0
    RF = 1
    LB = 2
    RB = 3

    @property
    def is_front(self) -> bool:
        return self in (Leg.LF, Leg.RF)

    @property
    def side(self) -> float:
        """+1 for a left leg, -1 for a right one (+z is the horse's left)."""
        return 1.0 if self in (Leg.LF, Leg.LB) else -1.0


WITHERS_HEIGHT = 1.60
"""Withers height of the default horse (m): a 16-hand riding horse."""


@dataclass(frozen=True, slots=True)
class Harmonic:
    """``amplitude * cos(2 pi k (phase - at))``: peak ``amplitude`` at stride fraction ``at``."""

    amplitude: float
    k: int = 1
    at: float = 0.0


NO_MOTION = Harmonic(0.0)


@dataclass(frozen=True, slots=True)
class GaitSpec:
    """One gait: support profile, speed and frequency ranges, trunk motion.

    ``offset`` and ``duty`` are per leg in :class:`Leg` order; ``lift`` is the peak
    transfer height of a front and a hind hoof (m). The trunk channels are harmonics
    of the stride phase: ``heave`` (rearPivot.ty, m), ``pitch`` (rearPivot.rz, deg,
    + nose up), ``roll`` (rearPivot.rx), ``yaw`` (rearPivot.ry), ``bend``
    (backMid.rz), ``sway`` (rearPivot.tz, m), ``surge`` (rearPivot.tx, m).
    """

    gait: Gait
    speed: tuple[float, float]
    default_speed: float
    frequency: tuple[float, float]
    offset: tuple[float, float, float, float]
    duty: tuple[float, float, float, float]
    lift: tuple[float, float]
    heave: Harmonic
    pitch: Harmonic
    roll: Harmonic
    yaw: Harmonic
    bend: Harmonic
    sway: Harmonic
    surge: Harmonic
    neck: Harmonic = NO_MOTION
    """``horseNeck.rz``: the neck's nod at the withers relative to the trunk (deg, + up)."""
    neck_side: Harmonic = NO_MOTION
    """``horseNeck.ry``: the neck's swing relative to the trunk (deg, + left)."""
    head: Harmonic = NO_MOTION
    """``horseHead.rz``: the head's nod at the poll relative to the neck (deg, + nose up)."""

    def frequency_at(self, speed: float) -> float:
        """Stride frequency (Hz) at ``speed`` (m/s): linear across the ranges."""
        (v0, v1), (f0, f1) = self.speed, self.frequency
        return f0 + (f1 - f0) * (speed - v0) / (v1 - v0)

    @property
    def frequency_slope(self) -> tuple[float, float]:
        """``(a, b)`` with ``frequency_at(v) == a + b * v`` (phase integrates in closed form)."""
        (v0, v1), (f0, f1) = self.speed, self.frequency
        b = (f1 - f0) / (v1 - v0)
        return f0 - b * v0, b

    def check_speed(self, speed: float) -> float:
        lo, hi = self.speed
        if not (lo <= speed <= hi):
            raise ValueError(f"{self.gait.value} speed must be within {lo}-{hi} m/s, got {speed!r}")
        return float(speed)


# Trunk heave peaks (lowest point) at mid-support: a negative cosine amplitude.
GAIT_TABLE: dict[Gait, GaitSpec] = {
    Gait.WALK: GaitSpec(
        gait=Gait.WALK,
        speed=(1.4, 1.8),
        default_speed=1.6,
        frequency=(0.67, 1.0),
        # four-beat lateral sequence: LB, LF, RB, RF a quarter stride apart
        offset=(0.25, 0.75, 0.0, 0.5),
        duty=(0.62, 0.62, 0.64, 0.64),
        lift=(0.11, 0.08),
        heave=Harmonic(-0.025, 2, 0.2),
        pitch=Harmonic(1.1, 2, 0.05),  # the saddle's pitch is this plus the back's bend
        roll=Harmonic(2.0, 1, 0.3),
        yaw=Harmonic(2.5, 1, 0.05),
        bend=Harmonic(2.5, 2, 0.1),
        sway=Harmonic(0.02, 1, 0.3),
        surge=Harmonic(0.01, 2, 0.0),
        # the head nods down as each forehoof is placed (LF 0.25, RF 0.75): twice per stride
        neck=Harmonic(-3.0, 2, 0.3),
        neck_side=Harmonic(1.5, 1, 0.3),
        head=Harmonic(-1.5, 2, 0.3),
    ),
    Gait.TROT: GaitSpec(
        gait=Gait.TROT,
        speed=(3.2, 4.9),
        default_speed=3.8,
        frequency=(0.92, 1.5),
        # two-beat diagonal: LF+RB, then RF+LB, with a suspension after each
        offset=(0.0, 0.5, 0.5, 0.0),
        duty=(0.40, 0.40, 0.40, 0.40),
        lift=(0.18, 0.14),
        heave=Harmonic(-0.036, 2, 0.2),
        pitch=Harmonic(2.0, 2, 0.1),
        roll=Harmonic(2.5, 1, 0.2),
        yaw=Harmonic(1.5, 1, 0.6),
        bend=Harmonic(2.0, 2, 0.1),
        sway=Harmonic(0.009, 1, 0.2),
        surge=Harmonic(0.015, 2, 0.0),
        neck=Harmonic(-0.5, 2, 0.1),  # steady: a trace against the trunk's pitch
    ),
    Gait.CANTER: GaitSpec(
        gait=Gait.CANTER,
        speed=(3.3, 6.0),
        default_speed=4.5,
        frequency=(1.33, 2.0),
        # three-beat, left lead: RB, then LB+RF together, then LF, then suspension
        offset=(0.45, 0.25, 0.25, 0.0),
        duty=(0.42, 0.42, 0.40, 0.40),
        lift=(0.20, 0.16),
        heave=Harmonic(-0.045, 1, 0.45),
        pitch=Harmonic(7.0, 1, 0.1),
        roll=Harmonic(2.0, 1, 0.3),
        yaw=Harmonic(2.0, 1, 0.3),
        bend=Harmonic(4.0, 1, 0.2),
        sway=Harmonic(0.012, 1, 0.3),
        surge=Harmonic(0.03, 1, 0.6),
        # one nod per stride, down as the forehand rises (against the trunk's pitch)
        neck=Harmonic(-6.0, 1, 0.1),
        head=Harmonic(-3.0, 1, 0.1),
    ),
    Gait.GALLOP: GaitSpec(
        gait=Gait.GALLOP,
        speed=(9.0, 17.0),
        default_speed=12.0,
        frequency=(2.0, 2.4),
        # four-beat transverse gallop, left lead, one airborne phase after LF
        offset=(0.44, 0.32, 0.12, 0.0),
        duty=(0.22, 0.22, 0.22, 0.22),
        lift=(0.30, 0.26),
        heave=Harmonic(-0.05, 1, 0.35),
        pitch=Harmonic(6.0, 1, 0.15),
        roll=Harmonic(1.5, 1, 0.3),
        yaw=Harmonic(1.0, 1, 0.3),
        bend=Harmonic(5.0, 1, 0.1),
        sway=Harmonic(0.01, 1, 0.3),
        surge=Harmonic(0.04, 1, 0.6),
        neck=Harmonic(-5.0, 1, 0.15),
        head=Harmonic(-2.0, 1, 0.15),
    ),
}
"""The four gaits; see ``docs/horse.md`` for the sources of every range."""

GAITS: tuple[str, ...] = tuple(g.value for g in GAIT_TABLE)
"""Gait names accepted by the API, the CLI and shot scripts (``halt`` too, not listed)."""


def parse_gait(name: str | Gait) -> Gait:
    """A :class:`Gait` from its name; ``ValueError`` names the choices."""
    if isinstance(name, Gait):
        return name
    try:
        return Gait(str(name).strip().lower())
    except ValueError:
        raise ValueError(f"unknown gait {name!r}; choose one of {', '.join((*GAITS, 'halt'))}") from None
