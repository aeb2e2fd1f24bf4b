"""Mocap-like damage to a clean rider take (seeded): how the fit is tested and benchmarked under noise.

:func:`mocap` applies, in this order: Gaussian noise (``rotation_sd`` degrees on rotations,
``translation_sd`` metres on translations), a linear drift of ``drift`` m/s on each
translation channel (its sign random per channel), a clock offset (the rider's clock reads
``clock`` seconds behind the horse's: rider time + ``clock`` = horse time), and dropped
frames (each frame lost with probability ``dropped``). The unitless hair and cloth
attributes are left out: mocap does not record them. Translations are in the take's
length unit, ``scale`` thesis rig units (``riderlive.frameunits``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from riderlive.channels import Kind, lookup
from riderlive.fit.problem import RiderTake
from riderlive.frameunits import METRES


@dataclass(frozen=True)
class Mocap:
    """The damage :func:`mocap` does (defaults: issue 27's figures)."""

    rotation_sd: float = 0.3  # degrees
    translation_sd: float = 0.003  # metres
    drift: float = 0.02  # metres per second
    dropped: float = 0.10  # fraction of frames lost
    clock: float = 0.2  # seconds


def mocap(take: RiderTake, scale: float, seed: int, damage: Mocap = Mocap()) -> RiderTake:
    """``take`` as mocap would record it (see the module docstring)."""
    rng = np.random.default_rng(seed)
    keep = [c for c, n in enumerate(take.names) if lookup(n).kind is not Kind.ATTRIBUTE]
    names = tuple(take.names[c] for c in keep)
    values = take.values[:, keep].copy()
    metres = METRES / scale  # take units per metre
    elapsed = take.t - take.t[0]
    for c, name in enumerate(names):
        if lookup(name).kind is Kind.ROTATION:
            values[:, c] += rng.normal(0.0, damage.rotation_sd, len(values))
        else:
            values[:, c] += rng.normal(0.0, damage.translation_sd * metres, len(values))
            values[:, c] += rng.choice((-1.0, 1.0)) * damage.drift * metres * elapsed
    kept = rng.random(len(values)) >= damage.dropped
    return RiderTake(f"{take.name} (mocap)", take.t[kept] - damage.clock, names, values[kept], take.sha256)
