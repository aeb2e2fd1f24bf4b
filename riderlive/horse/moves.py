"""The movements: jump, rear, sliding stop and buck, as support profiles and trunk keys.

Each leg is planned the way Girard's PODA plans a gait, as alternating support and
transfer: a :class:`Support` holds the hoof on the ground from placement to lift-off
(its ``tx`` moving linearly), a :class:`Transfer` carries it from lift-off to the next
placement through a peak ``height`` (held for ``hold`` seconds) with the hoof at
``mid`` forward/back. The trunk follows key poses through a monotone cubic (no
overshoot). Everything becomes one :class:`~riderlive.horse.layers.Spline` on shared
knots, C1 in every channel. Times in seconds from the start of the movement, lengths
in metres, angles in degrees; the stages follow the thesis' section 5.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from riderlive.horse.gaits import Leg
from riderlive.horse.layers import PADDLE, Spline


class Move(enum.Enum):
    JUMP = "jump"
    REAR = "rear"
    STOP = "stop"
    BUCK = "buck"


MOVES: tuple[str, ...] = tuple(m.value for m in Move)


def parse_move(name: str | Move) -> Move:
    if isinstance(name, Move):
        return name
    try:
        return Move(str(name).strip().lower())
    except ValueError:
        raise ValueError(f"unknown move {name!r}; choose one of {', '.join(MOVES)}") from None


@dataclass(frozen=True, slots=True)
class Support:
    """Hoof on the ground from ``on`` to ``off`` (s), ``tx`` going ``tx_on`` -> ``tx_off`` (m)."""

    on: float
    off: float
    tx_on: float
    tx_off: float


@dataclass(frozen=True, slots=True)
class Transfer:
    """Hoof in the air between two supports: peak ``height`` (m) held ``hold`` s at ``tx = mid``."""

    height: float
    hold: float = 0.0
    mid: float | None = None


Plan = tuple[Support | Transfer, ...]
# (tau, surge, heave, sway, roll, yaw, pitch, bend): rearPivot.tx ty tz rx ry rz, backMid.rz
Key = tuple[float, float, float, float, float, float, float, float]
# (tau, neck, neck side, head): horseNeck.rz, horseNeck.ry, horseHead.rz (deg)
HeadKey = tuple[float, float, float, float]


@dataclass(frozen=True)
class MoveSpec:
    """A movement: per-leg plans, trunk keys, named stages, and the root's speed."""

    move: Move
    legs: dict[Leg, Plan]
    body: tuple[Key, ...]
    stages: tuple[tuple[str, float, float], ...]
    speed: float  # target ground speed while moving (m/s)
    omega: float  # how fast the ground speed settles (1/s)
    resumes_gait: bool  # True: back to the gait it started from; False: halt
    head: tuple[HeadKey, ...] = ((0.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    spline: Spline = field(init=False)
    """The body channels (hooves and trunk)."""
    head_spline: Spline = field(init=False)
    """The neck and head (``channels.HORSE_NECK_HEAD``), held after their last key."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "spline", build_spline(self))
        object.__setattr__(self, "head_spline", _keys_spline([], self.head))

    @property
    def duration(self) -> float:
        return self.spline.duration

    def stage(self, name: str) -> tuple[float, float]:
        for stage, start, end in self.stages:
            if stage == name:
                return start, end
        raise KeyError(name)


Channel = tuple[list[float], list[float], list[float]]  # knots, values, slopes


def _leg_channels(plan: Plan, side: float) -> tuple[Channel, Channel, Channel]:
    """Hermite data (knots, values, slopes) for one hoof's tx, ty, tz."""
    tx: Channel = ([], [], [])
    ty: Channel = ([], [], [])
    tz: Channel = ([], [], [])

    def put(ch: Channel, t: float, v: float, m: float) -> None:
        ch[0].append(t)
        ch[1].append(v)
        ch[2].append(m)

    supports = [s for s in plan if isinstance(s, Support)]
    transfers = [s for s in plan if isinstance(s, Transfer)]
    if len(transfers) != len(supports) - 1 or not isinstance(plan[0], Support) or plan[0].on != 0.0:
        raise ValueError("a leg plan alternates supports and transfers and starts in support at 0")

    def slope(s: Support) -> float:
        return (s.tx_off - s.tx_on) / (s.off - s.on) if s.off > s.on else 0.0

    for i, sup in enumerate(supports):
        m = slope(sup)
        first, last = i == 0, i == len(supports) - 1
        put(tx, sup.on, sup.tx_on, 0.0 if first else m)
        if sup.off > sup.on:
            put(tx, sup.off, sup.tx_off, 0.0 if last else m)
        for ch in (ty, tz):
            put(ch, sup.on, 0.0, 0.0)
            if sup.off > sup.on:
                put(ch, sup.off, 0.0, 0.0)
        if last:
            break
        tr, nxt = transfers[i], supports[i + 1]
        rise = (nxt.on - sup.off - tr.hold) / 2.0
        mid = tr.mid if tr.mid is not None else (sup.tx_off + nxt.tx_on) / 2.0
        arc = side * PADDLE * min(1.0, tr.height / 0.2)
        for t in (sup.off + rise, nxt.on - rise) if tr.hold > 0.0 else (sup.off + rise,):
            put(
                tx,
                t,
                mid,
                0.0 if tr.hold > 0.0 or tr.mid is not None else (nxt.tx_on - sup.tx_off) / (nxt.on - sup.off),
            )
            put(ty, t, tr.height, 0.0)
            put(tz, t, arc, 0.0)
    return tx, ty, tz


def _pchip_slopes(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson slopes: a monotone cubic through the keys, flat at both ends."""
    h = np.diff(t)
    d = np.diff(y) / h
    m = np.zeros_like(y)
    for i in range(1, len(y) - 1):
        if d[i - 1] * d[i] > 0.0:
            w1, w2 = 2 * h[i] + h[i - 1], h[i] + 2 * h[i - 1]
            m[i] = (w1 + w2) / (w1 / d[i - 1] + w2 / d[i])
    return m


def _hermite_eval(ch: Channel, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Value and slope of one channel's Hermite curve at times ``t`` (exact knot insertion)."""
    k, v, m = (np.asarray(a, dtype=np.float64) for a in ch)
    i = np.clip(np.searchsorted(k, t, side="right") - 1, 0, len(k) - 2)
    h = k[i + 1] - k[i]
    u = np.clip((t - k[i]) / h, 0.0, 1.0)
    p0, p1, m0, m1 = v[i], v[i + 1], m[i] * h, m[i + 1] * h
    val = (2 * u**3 - 3 * u**2 + 1) * p0 + (u**3 - 2 * u**2 + u) * m0 + (3 * u**2 - 2 * u**3) * p1 + (u**3 - u**2) * m1
    der = (
        (6 * u**2 - 6 * u) * p0 + (3 * u**2 - 4 * u + 1) * m0 + (6 * u - 6 * u**2) * p1 + (3 * u**2 - 2 * u) * m1
    ) / h
    return val, der


def build_spline(spec: MoveSpec) -> Spline:
    """Every body channel of ``spec`` as one spline on the union of all knots."""
    channels: list[Channel] = []
    for leg in Leg:
        channels.extend(_leg_channels(spec.legs[leg], leg.side))
    return _keys_spline(channels, spec.body)


def _keys_spline(channels: list[Channel], table: tuple[tuple[float, ...], ...]) -> Spline:
    """``channels`` and the key table's columns (``tau`` first) as one spline on the union of their knots."""
    keys = np.array(table, dtype=np.float64)
    for c in range(1, keys.shape[1]):
        channels.append((keys[:, 0].tolist(), keys[:, c].tolist(), _pchip_slopes(keys[:, 0], keys[:, c]).tolist()))
    knots = np.unique(np.concatenate([np.asarray(ch[0]) for ch in channels]))
    values = np.empty((len(knots), len(channels)))
    slopes = np.empty_like(values)
    for c, ch in enumerate(channels):
        values[:, c], slopes[:, c] = _hermite_eval(ch, knots)
    return Spline.from_hermite(knots, values, slopes)


S, T = Support, Transfer

JUMP = MoveSpec(
    move=Move.JUMP,
    legs={
        Leg.LF: (
            S(0, 0.12, -0.3, -0.75),
            T(0.2),
            S(0.34, 0.52, 0.5, -0.45),
            T(1.25, 0.3, 0.15),
            S(1.62, 1.78, 0.5, -0.4),
            T(0.18),
            S(2.05, 2.6, 0.35, 0.0),
        ),
        Leg.RF: (
            S(0, 0.18, 0.1, -0.7),
            T(0.2),
            S(0.42, 0.58, 0.45, -0.5),
            T(1.2, 0.3, 0.1),
            S(1.70, 1.86, 0.5, -0.45),
            T(0.18),
            S(2.15, 2.6, 0.3, 0.0),
        ),
        Leg.LB: (
            S(0, 0.2, 0.3, -0.6),
            T(0.2),
            S(0.5, 0.9, 0.55, -0.4),
            T(1.05, 0.2, 0.0),
            S(1.9, 2.05, 0.45, -0.4),
            T(0.15),
            S(2.3, 2.6, 0.2, 0.0),
        ),
        Leg.RB: (
            S(0, 0.12, 0.0, -0.7),
            T(0.2),
            S(0.55, 0.92, 0.5, -0.45),
            T(1.0, 0.2, -0.05),
            S(1.95, 2.1, 0.45, -0.4),
            T(0.15),
            S(2.35, 2.6, 0.2, 0.0),
        ),
    },
    body=(
        (0.0, 0, 0, 0, 0, 0, 0, 0),
        (0.3, 0, -0.03, 0, 0, 0, -4, 0),
        (0.55, -0.05, -0.08, 0, 0, 0, 10, 2),
        (0.8, 0, 0.02, 0, 0, 0, 26, 4),
        (0.95, 0.05, 0.3, 0, 0, 0, 22, 0),
        (1.25, 0.05, 0.78, 0, 0, 0, 0, -6),
        (1.5, 0, 0.55, 0, 0, 0, -18, -4),
        (1.65, 0, 0.32, 0, 0, 0, -22, 0),
        (1.85, 0, 0.12, 0, 0, 0, -12, 2),
        (2.05, 0, -0.06, 0, 0, 0, 2, 0),
        (2.6, 0, 0, 0, 0, 0, 0, 0),
    ),
    stages=(
        ("approach", 0.0, 0.5),
        ("take-off", 0.5, 0.95),
        ("flight", 0.95, 1.6),
        ("landing", 1.6, 2.0),
        ("recovery", 2.0, 2.6),
    ),
    speed=6.0,
    omega=4.0,
    resumes_gait=True,
    # 5.1: the forehand rises at take-off, the neck reaches forward over the obstacle,
    # then rises again to prepare the landing
    head=((0.0, 0, 0, 0), (0.55, 4, 0, 2), (1.1, -14, 0, 6), (1.55, 8, 0, 0), (2.0, -4, 0, 0), (2.6, 0, 0, 0)),
)

REAR = MoveSpec(
    move=Move.REAR,
    legs={
        Leg.LF: (S(0, 0.6, 0, 0), T(1.05, 1.1, -0.3), S(2.75, 3.4, 0.05, 0.0)),
        Leg.RF: (S(0, 0.65, 0, 0), T(1.0, 1.0, -0.25), S(2.85, 3.4, 0.05, 0.0)),
        Leg.LB: (S(0, 0.1, 0, 0), T(0.08), S(0.4, 3.0, 0.25, 0.25), T(0.06), S(3.3, 3.4, 0.0, 0.0)),
        Leg.RB: (S(0, 0.25, 0, 0), T(0.08), S(0.55, 3.05, 0.25, 0.25), T(0.06), S(3.35, 3.4, 0.0, 0.0)),
    },
    body=(
        (0.0, 0, 0, 0, 0, 0, 0, 0),
        (0.6, 0, -0.05, 0, 0, 0, 4, 2),
        (1.3, -0.1, -0.25, 0, 2, 0, 48, 5),
        (1.7, -0.1, -0.27, 0, -2, 0, 54, 5),
        (2.1, -0.1, -0.25, 0, 0, 0, 48, 5),
        (2.8, 0, -0.04, 0, 0, 0, 3, 1),
        (3.4, 0, 0, 0, 0, 0, 0, 0),
    ),
    stages=(("gather", 0.0, 0.6), ("rise", 0.6, 1.3), ("hold", 1.3, 2.1), ("descend", 2.1, 2.8), ("settle", 2.8, 3.4)),
    speed=0.0,
    omega=3.0,
    resumes_gait=False,
    # 5.4: the head leans back to put more weight over the hind legs
    head=((0.0, 0, 0, 0), (0.6, 3, 0, 0), (1.3, 12, 0, 10), (2.1, 12, 0, 10), (2.8, 0, 0, 0), (3.4, 0, 0, 0)),
)

STOP = MoveSpec(
    move=Move.STOP,
    legs={
        Leg.LF: (
            S(0, 0.05, 0, -0.1),
            T(0.14),
            S(0.3, 0.7, 0.5, 0.2),
            T(0.1),
            S(0.95, 1.35, 0.45, 0.25),
            T(0.08),
            S(1.6, 2.3, 0.35, 0.1),
            T(0.06),
            S(2.55, 2.8, 0.0, 0.0),
        ),
        Leg.RF: (
            S(0, 0.15, 0, -0.1),
            T(0.14),
            S(0.42, 0.85, 0.5, 0.2),
            T(0.1),
            S(1.1, 1.5, 0.45, 0.25),
            T(0.08),
            S(1.75, 2.4, 0.3, 0.1),
            T(0.06),
            S(2.65, 2.8, 0.0, 0.0),
        ),
        Leg.LB: (S(0, 0.05, 0, -0.1), T(0.14), S(0.35, 1.95, 0.55, 0.45), T(0.1), S(2.25, 2.8, 0.0, 0.0)),
        Leg.RB: (S(0, 0.12, 0, -0.15), T(0.14), S(0.42, 2.0, 0.55, 0.45), T(0.1), S(2.35, 2.8, 0.0, 0.0)),
    },
    body=(
        (0.0, 0, 0, 0, 0, 0, 0, 0),
        (0.4, 0, -0.12, 0, 0, 0, 5, -3),
        (0.9, 0, -0.32, 0, 0, 0, 12, -8),
        (1.6, 0, -0.35, 0, 0, 0, 11, -8),
        (2.2, 0, -0.1, 0, 0, 0, 3, -2),
        (2.8, 0, 0, 0, 0, 0, 0, 0),
    ),
    stages=(("brace", 0.0, 0.5), ("slide", 0.5, 1.9), ("settle", 1.9, 2.8)),
    speed=0.0,
    omega=2.6,
    resumes_gait=False,
    # 5.5: the forehand is pushed up and back: the head comes up
    head=((0.0, 0, 0, 0), (0.9, 10, 0, 6), (1.6, 8, 0, 4), (2.8, 0, 0, 0)),
)


def _buck_front(lag: float) -> Plan:
    return (
        S(0, 0.1 + lag, 0, 0),
        T(0.5, 0.0, 0.15),
        S(0.55 + lag, 1.4 + lag, 0.1, 0.0),
        T(0.5, 0.0, 0.15),
        S(1.85 + lag, 2.6, 0.1, 0.0),
    )


def _buck_hind(lag: float) -> Plan:
    return (
        S(0, 0.35 + lag, 0, 0),
        T(0.6, 0.0, -0.3),
        S(0.95 + lag, 1.65 + lag, 0.0, 0.0),
        T(0.6, 0.0, -0.3),
        S(2.25 + lag, 2.6, 0.0, 0.0),
    )


BUCK = MoveSpec(
    move=Move.BUCK,
    legs={Leg.LF: _buck_front(0.0), Leg.RF: _buck_front(0.02), Leg.LB: _buck_hind(0.0), Leg.RB: _buck_hind(0.02)},
    body=(
        (0.0, 0, 0, 0, 0, 0, 0, 0),
        (0.2, 0, 0.1, 0.02, 6, 8, 15, -8),
        (0.45, 0, 0.35, 0.04, 10, 15, 0, -14),
        (0.7, 0, 0.3, 0.02, 6, 12, -20, -10),
        (1.0, 0, 0.0, 0, 0, 4, -5, -2),
        (1.3, 0, 0, 0, 0, 0, 0, 0),
        (1.5, 0, 0.1, -0.02, -6, -8, 15, -8),
        (1.75, 0, 0.35, -0.04, -10, -15, 0, -14),
        (2.0, 0, 0.3, -0.02, -6, -12, -20, -10),
        (2.3, 0, 0.0, 0, 0, -4, -5, -2),
        (2.6, 0, 0, 0, 0, 0, 0, 0),
    ),
    stages=(("buck left", 0.0, 1.3), ("buck right", 1.3, 2.6)),
    speed=1.0,
    omega=3.0,
    resumes_gait=False,
    # 5.6: "he puts his head down between his legs", with the side action of each buck
    head=(
        (0.0, 0, 0, 0),
        (0.45, -30, 6, -10),
        (0.7, -25, 4, -8),
        (1.0, -8, 0, -2),
        (1.3, 0, 0, 0),
        (1.75, -30, -6, -10),
        (2.0, -25, -4, -8),
        (2.3, -8, 0, -2),
        (2.6, 0, 0, 0),
    ),
)

MOVE_TABLE: dict[Move, MoveSpec] = {m.move: m for m in (JUMP, REAR, STOP, BUCK)}
