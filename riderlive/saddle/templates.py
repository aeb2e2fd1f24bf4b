"""What each gait's saddle looks like over one stride, from the procedural horse itself.

A template is the saddle pose of :class:`riderlive.horse.layers.GaitLayer` (the same
leg cycle and trunk harmonics the horse plays) through :mod:`riderlive.saddle.pose`,
reduced to its first two stride harmonics per channel: ``x(phase) ~ Re(sum_k T[c, k]
exp(i 2 pi k phase))`` for k = 1, 2, with ``phase`` the horse's own stride phase
(strides; hoof placements at the gait's ``offset``). The estimator matches measured
harmonics against these to find the gait and where in the stride the horse is.

``beats`` is the vertical's oscillations per stride: 2 in the walk and the trot, 1 in
the canter and the gallop (``docs/saddle.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
import numpy.typing as npt

from riderlive.horse.curves import ARRAY as HORSE_ARRAY
from riderlive.horse.curves import Ramp
from riderlive.horse.gaits import GAIT_TABLE, Gait, GaitSpec
from riderlive.horse.layers import GaitLayer
from riderlive.horse.model import to_rig_sides
from riderlive.saddle.pose import ARRAY, SaddlePoint, saddle_from_trunk

ComplexArray = npt.NDArray[np.complex128]
SAMPLES = 256
"""Phases per stride the templates are computed from."""
TRUNK_SLICE = slice(12, 18)
"""rearPivot.tx .. rz among a layer's body channels (after the twelve hoof channels)."""
BEND = 18
CHANNEL_SCALE: npt.NDArray[np.float64] = np.array([0.02, 0.02, 0.02, 2.0, 2.0, 2.0])
"""A typical oscillation amplitude per saddle channel (m, deg): channels count alike in the fits."""
WEIGHT: npt.NDArray[np.float64] = 1.0 / (CHANNEL_SCALE * CHANNEL_SCALE)


def size_of(harmonics: ComplexArray) -> float:
    """The weighted size of harmonics (6, 2): about 1 per channel oscillating at its typical amplitude."""
    return math.sqrt(float(WEIGHT @ (harmonics.real**2 + harmonics.imag**2).sum(axis=1)))


@dataclass(frozen=True)
class Template:
    """One gait's saddle harmonics: ``harmonics`` is (6 channels in SADDLE order, 2) complex."""

    gait: Gait
    spec: GaitSpec
    beats: int
    harmonics: ComplexArray
    layer: GaitLayer
    size: float

    def speed_at(self, frequency: float) -> float:
        """Ground speed (m/s) whose stride frequency is ``frequency`` (Hz), clamped to the gait's range."""
        a, b = self.spec.frequency_slope
        lo, hi = self.spec.speed
        return min(max((frequency - a) / b, lo), hi)


def _layer(spec: GaitSpec) -> GaitLayer:
    v = spec.default_speed
    return GaitLayer(spec, Ramp(0.0, v, 0.0, v, 3.0))


@cache
def templates(point: SaddlePoint) -> dict[Gait, Template]:
    """Every gait's template for a saddle at ``point`` (computed once per point)."""
    phases = np.arange(SAMPLES, dtype=np.float64) / SAMPLES
    out: dict[Gait, Template] = {}
    for gait, spec in GAIT_TABLE.items():
        layer = _layer(spec)
        body = to_rig_sides(layer.pose_at(phases, spec.default_speed, HORSE_ARRAY))
        trunk = [np.broadcast_to(np.asarray(v, dtype=np.float64), phases.shape) for v in body[TRUNK_SLICE]]
        saddle = np.column_stack(saddle_from_trunk(trunk, np.asarray(body[BEND]), point, ARRAY))
        spectrum = np.fft.rfft(saddle, axis=0) * (2.0 / SAMPLES)
        harmonics = np.ascontiguousarray(spectrum[1:3].T)  # (channels, k = 1, 2)
        beats = 1 if abs(harmonics[1, 0]) >= abs(harmonics[1, 1]) else 2
        out[gait] = Template(gait, spec, beats, harmonics, layer, size_of(harmonics))
    return out
