"""The saddle motion stream: the saddle pose out of any horse, and a rider from a saddle alone.

- :mod:`~riderlive.saddle.pose`: ``channels.SADDLE`` (``saddle.tx ty tz rx ry rz``,
  metres and degrees) from any horse frame, and back; one source for floats and NumPy.
- :mod:`~riderlive.saddle.estimator`: ``Model`` / ``State`` / ``step(model, state, t,
  values)``: saddle samples in, gait, stride frequency, phase and lock out; no clock.
  :mod:`~riderlive.saddle.estimate`: ``estimate(state, t)``, the publishable view.
- :mod:`~riderlive.saddle.rebuild`: ``horse_frame(model, state, t)``, the horse the
  rules ride (the procedural horse's hooves at the estimated gait and phase, the
  measured trunk); ``rebuild`` for a whole take.
- :mod:`~riderlive.saddle.synthetic`: seeded, realistic synthetic recordings.

See ``docs/saddle.md``.
"""

from __future__ import annotations

from riderlive.saddle.estimate import estimate
from riderlive.saddle.estimator import Lock, Model, State, step
from riderlive.saddle.pose import (
    BACK_MID,
    WITHERS,
    SaddlePoint,
    saddle_from_horse,
    saddle_from_trunk,
    saddle_matrix,
    trunk_from_saddle,
)
from riderlive.saddle.rebuild import horse_frame, rebuild

__all__ = [
    "BACK_MID",
    "WITHERS",
    "Lock",
    "Model",
    "SaddlePoint",
    "State",
    "estimate",
    "horse_frame",
    "rebuild",
    "saddle_from_horse",
    "saddle_from_trunk",
    "saddle_matrix",
    "step",
    "trunk_from_saddle",
]
