"""Trials: a synthetic saddle recording through the estimator, against the rider of the full horse.

The measure behind ``docs/saddle.md``'s table, shared by the tests and
``bench/bench_saddle_table.py``: record a procedural take's saddle
(:mod:`riderlive.saddle.synthetic`), rebuild a horse from it (:func:`rebuild`), and
drive the rider rules with both the full horse frames (the truth) and the rebuilt
ones, frame for frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.channels import RIDER_INDEX
from riderlive.horse import DEFAULT_SCALE, GAIT_TABLE, Gait
from riderlive.horse.script import ShotScript, gait_script
from riderlive.rules import RiderModel
from riderlive.saddle.estimator import Model
from riderlive.saddle.rebuild import Rebuilt, rebuild
from riderlive.saddle.synthetic import Imperfections, RateSchedule, Recording, record

FloatArray = npt.NDArray[np.float64]
RIDER = RiderModel(scale=DEFAULT_SCALE)
COMPARED = ("lower_back.rz", "cog.ty", "hip.ry", "head.rz")
"""The rider channels the issue compares."""


@dataclass(frozen=True)
class Trial:
    recording: Recording
    rebuilt: Rebuilt
    truth: FloatArray  # the rider driven by the full horse frames
    estimated: FloatArray  # the rider driven by the rebuilt horse

    @property
    def t(self) -> FloatArray:
        assert self.recording.saddle.t is not None
        return self.recording.saddle.t

    def locked_from(self, gait: str, after: float = -np.inf) -> float | None:
        """The time from which the estimator reports ``gait`` locked to the end (None: never)."""
        pairs = zip(self.rebuilt.lock, self.rebuilt.gait, strict=True)
        ok = np.array([lock == "locked" and g == gait for lock, g in pairs])
        bad = np.flatnonzero(~ok & (self.t >= after))
        first = int(bad[-1]) + 1 if len(bad) else int(np.searchsorted(self.t, after))
        return float(self.t[first]) if first < len(self.t) else None

    def correlations(self, since: float) -> dict[str, float]:
        """Per compared channel, the correlation of estimated and true rider from ``since`` (s)."""
        rows = self.t >= since
        return {
            c: float(np.corrcoef(self.truth[rows, RIDER_INDEX[c]], self.estimated[rows, RIDER_INDEX[c]])[0, 1])
            for c in COMPARED
        }


def trial(
    script: ShotScript,
    rate: RateSchedule = 120.0,
    *,
    start: float = 0.0,
    imperfections: Imperfections | None = None,
    seed: int = 0,
    model: Model | None = None,
) -> Trial:
    """Record ``script``'s saddle and run it through the estimator."""
    model = model or Model()
    recording = record(script, rate, start=start, imperfections=imperfections, seed=seed, point=model.point)
    assert recording.saddle.t is not None
    rebuilt = rebuild(model, recording.saddle.t, recording.saddle.values)
    return Trial(recording, rebuilt, RIDER.evaluate_batch(recording.horse.values), RIDER.evaluate_batch(rebuilt.horse))


@dataclass(frozen=True)
class GaitCase:
    """One seeded case of a steady gait: a speed in the gait's range, a rate, a start mid-stride."""

    gait: str
    seed: int
    speed: float
    stride_hz: float
    rate: float
    start: float

    @staticmethod
    def draw(gait: str, seed: int, rates: tuple[float, ...] = (30.0, 120.0, 500.0)) -> GaitCase:
        spec = GAIT_TABLE[Gait(gait)]
        rng = np.random.default_rng([seed, list(GAIT_TABLE).index(Gait(gait))])
        speed = float(rng.uniform(*spec.speed))
        stride = spec.frequency_at(speed)
        return GaitCase(gait, seed, speed, stride, float(rng.choice(rates)), float(rng.uniform(0.0, 1.0 / stride)))

    def run(self, seconds: float, imperfections: Imperfections | None = None, model: Model | None = None) -> Trial:
        script = gait_script(self.gait, seconds, self.speed, seed=self.seed + 1)
        return trial(script, self.rate, start=self.start, imperfections=imperfections, seed=self.seed, model=model)
