"""Motion and thermal model of an emulated servo: pure state in, state out.

Units: positions in pulses (1/4096 turn), velocities in pulses/s, accelerations in
pulses/s^2, temperatures in deg C, time in seconds. The servo tracks its profile
exactly (present position = position trajectory): tracking error in the emulator comes
only from the profile limits, as on a well-tuned, lightly loaded servo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from riderlive.dynamixel.tables import ACCELERATION_UNIT_RPM2, PULSES_PER_TURN, VELOCITY_UNIT_RPM

SUBSTEP_S = 0.001
"""Fixed integration step of the profile, s."""
SETTLE_PULSES = 0.5
"""Distance below which a slow trajectory snaps onto its goal, pulses."""


def velocity_from_register(value: int) -> float:
    """Pulses/s for a velocity register value (0.229 rev/min units)."""
    return value * VELOCITY_UNIT_RPM * PULSES_PER_TURN / 60.0


def velocity_to_register(pulses_per_s: float) -> int:
    return round(pulses_per_s * 60.0 / (VELOCITY_UNIT_RPM * PULSES_PER_TURN))


def acceleration_from_register(value: int) -> float:
    """Pulses/s^2 for a Profile Acceleration value (214.577 rev/min^2 units)."""
    return value * ACCELERATION_UNIT_RPM2 * PULSES_PER_TURN / 3600.0


@dataclass(frozen=True)
class ThermalParams:
    """First-order thermal model: dT/dt = (ambient + rise * effort^2 - T) / time_constant."""

    ambient_c: float = 25.0
    full_effort_rise_c: float = 80.0
    time_constant_s: float = 120.0


@dataclass(frozen=True)
class Profile:
    """What the servo is asked to do during one step (from its registers)."""

    torque_on: bool
    goal_position: float
    max_velocity: float
    """Profile velocity cap, pulses/s (> 0)."""
    max_acceleration: float
    """Profile acceleration cap, pulses/s^2; ``math.inf`` for a step change of velocity."""
    goal_velocity: float | None = None
    """Velocity Control Mode target, pulses/s; None in position modes."""
    external_load: float = 0.0
    """Extra effort fraction from outside (a test pushing on the horn), 0..1."""


@dataclass(frozen=True)
class MotionState:
    position: float
    velocity: float = 0.0
    acceleration: float = 0.0
    temperature: float = 25.0
    effort: float = 0.0
    """Fraction of the servo's torque in use, 0..1 (drives current/load and heat)."""

    @property
    def moving(self) -> bool:
        return abs(self.velocity) > 1e-9


ACCEL_FOR_FULL_EFFORT = 40_000.0
"""Profile acceleration that takes the whole torque of an unloaded servo, pulses/s^2."""
HOLDING_EFFORT = 0.02
"""Effort of holding position with torque on and no load."""


def _approach(  # noqa: PLR0917
    position: float, velocity: float, goal: float, vmax: float, amax: float, dt: float
) -> tuple[float, float]:
    """One substep of a trapezoidal (velocity- and acceleration-capped) move to ``goal``.

    Semi-implicit Euler; the braking speed ``a(sqrt(dt^2/4 + 2d/a) - dt/2)`` is the one
    from which decelerating by ``a dt`` per substep stops exactly at the goal.
    """
    distance = goal - position
    direction = math.copysign(1.0, distance)
    if math.isinf(amax):
        target = direction * min(vmax, abs(distance) / dt)
        return (goal, 0.0) if abs(distance) <= vmax * dt else (position + target * dt, target)
    brake = amax * (math.sqrt(dt * dt / 4.0 + 2.0 * abs(distance) / amax) - dt / 2.0)
    target = direction * min(vmax, brake)
    new_velocity = velocity + max(-amax * dt, min(amax * dt, target - velocity))
    new_position = position + new_velocity * dt
    if (goal - new_position) * direction <= 0 or abs(goal - new_position) < SETTLE_PULSES * 1e-3:
        return goal, 0.0  # arrives within this substep
    return new_position, new_velocity


def _track_velocity(velocity: float, goal: float, amax: float, dt: float) -> float:
    if math.isinf(amax):
        return goal
    return velocity + max(-amax * dt, min(amax * dt, goal - velocity))


def step(state: MotionState, profile: Profile, dt: float, thermal: ThermalParams = ThermalParams()) -> MotionState:
    """Advance ``state`` by ``dt`` seconds under ``profile`` (equal substeps of at most SUBSTEP_S)."""
    position, velocity = state.position, state.velocity
    accel = 0.0
    if profile.torque_on and dt > 0:
        substeps = math.ceil(dt / SUBSTEP_S - 1e-9)
        h = dt / substeps
        for _ in range(substeps):
            before = velocity
            if profile.goal_velocity is not None:
                velocity = _track_velocity(velocity, profile.goal_velocity, profile.max_acceleration, h)
                position += 0.5 * (before + velocity) * h
            else:
                if position == profile.goal_position and velocity == 0.0:
                    accel = 0.0
                    break  # settled: nothing moves until the goal changes
                position, velocity = _approach(
                    position, velocity, profile.goal_position, profile.max_velocity, profile.max_acceleration, h
                )
            accel = (velocity - before) / h
    else:
        velocity = 0.0
    effort = 0.0
    if profile.torque_on:
        effort = min(1.0, HOLDING_EFFORT + abs(accel) / ACCEL_FOR_FULL_EFFORT + profile.external_load)
    steady = thermal.ambient_c + thermal.full_effort_rise_c * effort * effort
    temperature = steady + (state.temperature - steady) * math.exp(-dt / thermal.time_constant_s)
    return MotionState(position, velocity, accel, temperature, effort)


def holding_effort(profile: Profile) -> float:
    """Effort of a servo that is not accelerating under ``profile``."""
    return min(1.0, HOLDING_EFFORT + profile.external_load) if profile.torque_on else 0.0


def seconds_until_temperature(
    state: MotionState, effort: float, limit_c: float, thermal: ThermalParams
) -> float | None:
    """When the temperature reaches ``limit_c`` at constant ``effort`` (None: never)."""
    steady = thermal.ambient_c + thermal.full_effort_rise_c * effort * effort
    if state.temperature >= limit_c:
        return 0.0
    if steady <= limit_c:
        return None
    return thermal.time_constant_s * math.log((steady - state.temperature) / (steady - limit_c))
