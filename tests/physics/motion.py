"""Synthetic horse takes for the physics tests: smooth, violent where it matters, no randomness.

``take(kind, rate)`` returns (times, frames) with frames in ``channels.HORSE`` order
(metres, degrees). Kinds: ``rest``, ``trot``, ``gallop``, ``buck``, ``trot_rear_gallop``.
The procedural horse's ``perform("rear")`` / ``perform("buck")`` replace these when it
is available (see :func:`horse_take`).
"""

from __future__ import annotations

import math

import numpy as np

from riderlive.channels import HORSE_INDEX, HORSE_NAMES


def _bump(t: float, start: float, stop: float) -> float:
    """0 outside [start, stop], rising and falling smoothly (sin^2) inside."""
    if t <= start or t >= stop:
        return 0.0
    return math.sin(math.pi * (t - start) / (stop - start)) ** 2


def _ramp(t: float, start: float, stop: float) -> float:
    if t <= start:
        return 0.0
    if t >= stop:
        return 1.0
    u = (t - start) / (stop - start)
    return u * u * (3.0 - 2.0 * u)


def _ramp_integral(t: float, start: float, stop: float, change: float) -> float:
    """Distance gained by a speed change of ``change`` (m/s) eased in over [start, stop]."""
    width = stop - start
    u = (t - start) / width
    if u <= 0.0:
        return 0.0
    if u >= 1.0:
        return change * width * (u - 0.5)
    return change * width * (u**3 - 0.5 * u**4)


def frame(kind: str, t: float) -> list[float]:
    """One horse frame of the synthetic take ``kind`` at time ``t`` (seconds)."""
    f = [0.0] * len(HORSE_NAMES)
    ix = HORSE_INDEX
    pitch = 0.0
    roll = 0.0
    yaw = 0.0
    lift = 0.0
    heading = 0.0
    x = 0.0
    if kind == "rest":
        pass
    elif kind in ("trot", "gallop"):
        fast = kind == "gallop"
        hz = 2.2 if fast else 1.3
        speed = 12.0 if fast else 4.0
        phase = 2.0 * math.pi * hz * t
        pitch = (8.0 if fast else 2.5) * math.sin(phase)
        lift = (0.10 if fast else 0.04) * math.sin(2.0 * phase if not fast else phase)
        roll = (3.0 if fast else 4.0) * math.sin(phase + 0.5)
        yaw = 2.0 * math.sin(phase)
        heading = 15.0 * math.sin(0.4 * t) if fast else 0.0
        x = speed * t
    elif kind == "buck":
        phase = 2.0 * math.pi * 1.0 * t
        kick = max(0.0, math.sin(phase)) ** 2
        pitch = -20.0 * kick
        lift = 0.25 * kick
        roll = 8.0 * math.sin(0.5 * phase)
        yaw = 10.0 * math.sin(0.5 * phase + 1.0)
        x = 2.0 * t
    elif kind == "trot_rear_gallop":
        # trot 0-3 s, rear 3-5.5 s (pitch up 40 deg, haunches down), gallop from 5.5 s
        gallop = _ramp(t, 5.0, 6.0)
        rear = _bump(t, 3.0, 5.5)
        phase = 2.0 * math.pi * (1.3 * t + _ramp_integral(t, 5.0, 6.0, 0.9))
        gait = 1.0 - rear
        pitch = gait * (2.5 + 5.5 * gallop) * math.sin(phase) + 40.0 * rear
        lift = gait * (0.04 + 0.06 * gallop) * math.sin(2.0 * phase) - 0.25 * rear
        roll = gait * 4.0 * math.sin(phase + 0.5)
        yaw = gait * 2.0 * math.sin(phase)
        heading = 20.0 * gallop * math.sin(0.5 * (t - 5.0))
        x = 4.0 * t + _ramp_integral(t, 2.5, 3.5, -3.5) + _ramp_integral(t, 5.0, 6.5, 10.5)
    else:
        raise ValueError(kind)
    h = math.radians(heading)
    f[ix["root.tx"]] = x * math.cos(h)
    f[ix["root.tz"]] = -x * math.sin(h)
    f[ix["root.ry"]] = heading
    f[ix["rearPivot.ty"]] = 1.05 + lift
    f[ix["rearPivot.rz"]] = pitch
    f[ix["rearPivot.rx"]] = roll
    f[ix["rearPivot.ry"]] = yaw
    for hoof, sign in (("lb", 1.0), ("rb", -1.0)):
        swing = math.sin(2.0 * math.pi * 1.5 * t) * sign if kind != "rest" else 0.0
        f[ix[f"{hoof}Hoof.tx"]] = -0.9 + 0.3 * swing
        f[ix[f"{hoof}Hoof.ty"]] = max(0.0, 0.15 * swing)
    for hoof in ("lf", "rf"):
        f[ix[f"{hoof}Hoof.tx"]] = 0.6
    return f


def take(kind: str, duration: float, rate: float = 240.0) -> tuple[np.ndarray, np.ndarray]:
    """(times, frames) of ``kind`` sampled at ``rate`` Hz for ``duration`` seconds."""
    times = np.arange(round(duration * rate) + 1) / rate
    return times, np.array([frame(kind, float(t)) for t in times])


class SyntheticHorse:
    """The live-source contract (``sample(t)``) over a synthetic take."""

    def __init__(self, kind: str) -> None:
        self.kind = kind

    def sample(self, t: float) -> list[float]:
        return frame(self.kind, t)
