"""From rider channels to servo units: the rig's per-tick arithmetic (pure).

:class:`ServoMap` flattens a validated :class:`~riderlive.dynamixel.rig.RigConfig` into
lists for the tick: each servo's goal in shaft degrees (``zero_deg + direction * gain *
channel``), clamped to its limits and slew-limited to its speed; the conversions between
degrees and the control table's units (position pulses, Profile Velocity and Acceleration,
Bus Watchdog, Return Delay Time) sit beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from riderlive.channels import RIDER_INDEX
from riderlive.dynamixel.rig import DEG_PER_PULSE, RigConfig
from riderlive.dynamixel.tables import (
    ACCELERATION_UNIT_RPM2,
    BUS_WATCHDOG_UNIT_S,
    POSITION_RANGE,
    RETURN_DELAY_UNIT_S,
    VELOCITY_UNIT_RPM,
)

# --- unit conversions (pure) ---------------------------------------------------------


def deg_to_pulses(deg: float) -> int:
    """Servo degrees -> Goal/Present Position pulses, clamped to the register range."""
    pulses = round(deg / DEG_PER_PULSE)
    return min(max(pulses, POSITION_RANGE[0]), POSITION_RANGE[1])


def pulses_to_deg(pulses: int) -> float:
    return pulses * DEG_PER_PULSE


def profile_velocity(dps: float) -> int:
    """Deg/s -> Profile Velocity (112) units of 0.229 rev/min (>= 1: 0 means unlimited)."""
    return max(1, round(dps / 6.0 / VELOCITY_UNIT_RPM))


def profile_acceleration(dps2: float) -> int:
    """Deg/s^2 -> Profile Acceleration (108) units of 214.577 rev/min^2 (0 = unlimited)."""
    if dps2 <= 0.0:
        return 0
    return max(1, round(dps2 * 10.0 / ACCELERATION_UNIT_RPM2))


def watchdog_units(ms: int) -> int:
    return round(ms / 1000.0 / BUS_WATCHDOG_UNIT_S)


def return_delay_units(us: int) -> int:
    return round(us * 1e-6 / RETURN_DELAY_UNIT_S)


# --- the map from rider channels to servo goals (pure) -----------------------------


class ServoMap:
    """The rig's servos as flat lists, for the per-tick arithmetic (degrees, seconds)."""

    def __init__(self, rig: RigConfig) -> None:
        servos = list(rig.servos.values())
        self.names: tuple[str, ...] = tuple(rig.servos)
        self.ids: tuple[int, ...] = tuple(s.id for s in servos)
        self.channels: tuple[int, ...] = tuple(RIDER_INDEX[s.channel] for s in servos)
        self.scale: tuple[float, ...] = tuple(s.direction * s.gain for s in servos)
        self.zero: tuple[float, ...] = tuple(s.zero_deg for s in servos)
        self.low: tuple[float, ...] = tuple(s.min_deg for s in servos)
        self.high: tuple[float, ...] = tuple(s.max_deg for s in servos)
        self.park: tuple[float, ...] = tuple(s.park for s in servos)
        self.speed: tuple[float, ...] = tuple(s.max_speed_dps for s in servos)

    def __len__(self) -> int:
        return len(self.ids)

    def targets(self, rider: Sequence[float], hold: Sequence[float]) -> list[float]:
        """Unclamped goal degrees for a rider frame; a non-finite value holds ``hold``."""
        out = []
        for i, ch in enumerate(self.channels):
            value = rider[ch]
            out.append(self.zero[i] + self.scale[i] * value if math.isfinite(value) else hold[i])
        return out

    def limit(self, targets: Sequence[float], previous: Sequence[float], dt: float) -> tuple[list[float], list[bool]]:
        """Clamp to [min, max], then slew-limit against ``previous`` over ``dt`` seconds.

        Returns the goals and, per servo, whether either limit changed the target.
        """
        goals: list[float] = []
        clamped: list[bool] = []
        dt = max(dt, 0.0)
        for i, target in enumerate(targets):
            goal = min(max(target, self.low[i]), self.high[i])
            step = self.speed[i] * dt
            prev = previous[i]
            goal = min(max(goal, prev - step), prev + step)
            goals.append(goal)
            clamped.append(abs(goal - target) > 1e-9)
        return goals, clamped

    def within_limits(self, positions: Sequence[float]) -> list[float]:
        """Positions clamped to [min, max] (a start pose outside the limits, say)."""
        return [min(max(p, lo), hi) for p, lo, hi in zip(positions, self.low, self.high, strict=True)]
