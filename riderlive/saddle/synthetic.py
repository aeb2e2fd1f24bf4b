"""Realistic synthetic saddle recordings: the procedural horse's saddle, as a real sensor would see it.

No public saddle recording is at hand, so tests and demos use these: the saddle pose
of a procedural take (a gait or a shot script, :mod:`riderlive.horse`) sampled at a
given rate (or a schedule of rates), from any start time (mid-stride), spoiled the way
an IMU strap on a saddle spoils it, all seeded:

- ``drift`` (m/s): the translations wander off at this speed in a random direction
  (double-integrated accelerometers); ``yaw_drift`` (deg/s) the heading (gyro);
- ``tilt`` (deg): pitch and roll read a constant offset (the strap is not level;
  gravity keeps an IMU's pitch and roll from drifting);
- ``noise`` (m) and ``angle_noise`` (deg): white noise, standard deviations;
- ``dropout``: the fraction of frames lost, at random.

:func:`record` returns the recording and, row for row, the horse frames it came from
(the ground truth the tests compare against).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_NAMES, SADDLE_NAMES
from riderlive.framefile import FrameTable
from riderlive.horse.model import evaluate
from riderlive.horse.script import ShotScript
from riderlive.saddle.pose import SaddlePoint, saddle_matrix

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Imperfections:
    """How a recording is spoiled; all zero is a perfect sensor."""

    drift: float = 0.0
    yaw_drift: float = 0.0
    tilt: float = 0.0
    noise: float = 0.0
    angle_noise: float = 0.0
    dropout: float = 0.0

    def __post_init__(self) -> None:
        for name in ("drift", "yaw_drift", "tilt", "noise", "angle_noise"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not (0.0 <= self.dropout < 1.0):
            raise ValueError(f"dropout must be within 0-1 (exclusive), got {self.dropout!r}")


IMU_STRAP = Imperfections(drift=0.02, yaw_drift=0.5, tilt=1.0, noise=0.005, angle_noise=0.3, dropout=0.1)
"""The issue's test case: 2 cm/s drift, 5 mm noise, 10 % of frames dropped (with a strap's yaw
drift, tilt and 0.3 deg of angle noise, chosen)."""


@dataclass(frozen=True)
class Recording:
    """A saddle recording (``t`` and ``channels.SADDLE``) and the horse frames it was made from."""

    saddle: FrameTable
    horse: FrameTable


RateSchedule = float | Sequence[tuple[float, float]]
"""A rate in Hz, or ``(until, rate)`` pairs: ``rate`` Hz until ``until`` seconds of the script."""


def sample_times(schedule: RateSchedule, start: float, stop: float) -> FloatArray:
    """Sample times (s) from ``start`` to before ``stop`` at the scheduled rates (10-1000 Hz)."""
    pieces = [(stop, float(schedule))] if isinstance(schedule, int | float) else list(schedule)
    times: list[FloatArray] = []
    t = start
    for until, rate in pieces:
        if not (10.0 <= rate <= 1000.0):
            raise ValueError(f"rates must be within 10-1000 Hz, got {rate!r}")
        end = min(until, stop)
        if end > t:
            times.append(t + np.arange(int(np.ceil((end - t) * rate - 1e-9))) / rate)
            t = float(times[-1][-1]) + 1.0 / rate if len(times[-1]) else t
    if not times:
        return np.empty(0)
    return np.concatenate(times)


def record(
    script: ShotScript,
    rate: RateSchedule = 120.0,
    *,
    start: float = 0.0,
    imperfections: Imperfections | None = None,
    seed: int = 0,
    point: SaddlePoint | None = None,
) -> Recording:
    """The saddle of ``script`` from ``start`` (s) to its end, as a spoiled sensor records it."""
    spoil = imperfections or Imperfections()
    times = sample_times(rate, start, script.duration)
    if len(times) == 0:
        raise ValueError("the recording is empty: start is past the script's end")
    model = script.model()
    _, horse = evaluate(model, script.start(model), times)
    saddle = saddle_matrix(horse, point)
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    elapsed = times - times[0]
    saddle[:, :3] += np.outer(elapsed, direction * spoil.drift)
    saddle[:, 4] += elapsed * spoil.yaw_drift * rng.choice((-1.0, 1.0))
    tilt = rng.normal(size=2)
    saddle[:, [3, 5]] += tilt / max(float(np.linalg.norm(tilt)), 1e-12) * spoil.tilt
    saddle[:, :3] += rng.normal(scale=spoil.noise, size=(len(times), 3)) if spoil.noise else 0.0
    saddle[:, 3:] += rng.normal(scale=spoil.angle_noise, size=(len(times), 3)) if spoil.angle_noise else 0.0
    keep = rng.random(len(times)) >= spoil.dropout
    keep[0] = True
    return Recording(
        FrameTable(SADDLE_NAMES, np.ascontiguousarray(saddle[keep]), times[keep].copy()),
        FrameTable(HORSE_NAMES, np.ascontiguousarray(horse[keep]), times[keep].copy()),
    )
