"""Saddle pose to actuator commands: cueing, IK with the workspace scale-back, the safety stage.

One frame (the tick, :func:`step`) and a whole take (:func:`bake`) run the same
sources: the cueing and limit kernels (compiled from their Python source) and the IK
of :mod:`riderlive.platform.mechanism.ik` on floats or on arrays. They agree to 1e-9 (tested).

:func:`aim` is the first half (cue, pose, actuator targets, workspace share); the
device lifecycle uses it while soft-starting, blending from where the actuators are to
these targets (:func:`riderlive.platform.mechanism.limits.eased`) before the safety stage.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from riderlive.platform.mechanism import cueing, limits
from riderlive.platform.mechanism.config import PlatformConfig, build_geometry, load_platform
from riderlive.platform.mechanism.cueing import CueingModel, CueingState
from riderlive.platform.mechanism.geometry import Geometry
from riderlive.platform.mechanism.ik import SCALAR, Workspace, axis_ranges, make_ik
from riderlive.platform.mechanism.limits import SafetyModel, SafetyState

FloatArray = npt.NDArray[np.float64]
CHUNK = 8192
"""Frames per piece of the batch IK: its temporaries stay in the CPU cache."""


@dataclass(frozen=True, eq=False)
class PlatformModel:
    """Everything static about one platform: geometry, cueing, workspace, limits, ease times (s)."""

    geometry: Geometry
    cueing: CueingModel
    soft_start_s: float = 3.0
    park_s: float = 3.0
    name: str = "platform"

    def __post_init__(self) -> None:
        object.__setattr__(self, "_workspace", Workspace(self.geometry))
        object.__setattr__(self, "_safety", SafetyModel.from_geometry(self.geometry))
        ik = make_ik(self.geometry, SCALAR)
        object.__setattr__(self, "_home_q", tuple(ik(*self.geometry.home)[0]))
        object.__setattr__(self, "_park_q", tuple(ik(*self.geometry.park)[0]))

    @classmethod
    def from_config(cls, cfg: PlatformConfig) -> PlatformModel:
        g = build_geometry(cfg)
        cue = CueingModel(cfg.cueing, axis_ranges(g), cfg.kind.axes)
        return cls(g, cue, cfg.soft_start_s, cfg.park_s, cfg.name)

    @classmethod
    def load(cls, path: str | Path) -> PlatformModel:
        """A platform file (or a shipped platform's name)."""
        return cls.from_config(load_platform(path))

    @property
    def workspace(self) -> Workspace:
        return self._workspace  # type: ignore[attr-defined,no-any-return]

    @property
    def safety(self) -> SafetyModel:
        return self._safety  # type: ignore[attr-defined,no-any-return]

    @property
    def home_positions(self) -> tuple[float, ...]:
        return self._home_q  # type: ignore[attr-defined,no-any-return]

    @property
    def park_positions(self) -> tuple[float, ...]:
        return self._park_q  # type: ignore[attr-defined,no-any-return]

    def with_cueing(self, **changes: Any) -> PlatformModel:
        """Live parameters: the same platform with cueing changes; a running state blends toward them."""
        return replace(self, cueing=self.cueing.with_params(**changes))


class PlatformState(NamedTuple):
    """The cueing and safety states and the number of frames the workspace scale-back acted on."""

    cueing: CueingState
    safety: SafetyState
    scaled_back: int = 0

    @property
    def counters(self) -> dict[str, int]:
        return {**self.cueing.counters, **self.safety.counters, "scaled_back_frames": self.scaled_back}


class Aim(NamedTuple):
    """Where one frame wants the platform: cue (relative to home), pose (base frame), targets, kept share."""

    cue: list[float]
    pose: tuple[float, ...]
    targets: tuple[float, ...]
    scale: float


class Frame(NamedTuple):
    """One tick's result: the aim and the commands after the safety stage."""

    aim: Aim
    positions: FloatArray


def initial(model: PlatformModel, positions: Any = None) -> PlatformState:
    """A state at rest at ``positions`` (the actuators' present positions; default home)."""
    start = model.home_positions if positions is None else positions
    return PlatformState(cueing.initial(model.cueing), SafetyState.at(start))


def aim(model: PlatformModel, state: CueingState, saddle: Any, dt: float) -> tuple[CueingState, Aim]:
    """Cue one saddle frame and solve its actuator targets (scaled back into the workspace)."""
    state, cue = cueing.step(model.cueing, state, saddle, dt)
    h = model.geometry.home
    pose = (h[0] + cue[0], h[1] + cue[1], h[2] + cue[2], h[3] + cue[3], h[4] + cue[4], h[5] + cue[5])
    targets, scale = model.workspace.fit(pose)
    if scale < 1.0:
        pose = tuple(a + scale * (p - a) for a, p in zip(h, pose, strict=True))  # type: ignore[assignment]
    return state, Aim(cue, pose, targets, scale)


def step(
    model: PlatformModel,
    state: PlatformState,
    saddle: Any,
    dt: float,
    ease: tuple[Sequence[float], float] | None = None,
) -> tuple[PlatformState, Frame]:
    """One frame: saddle pose in (6 values, m and deg), actuator commands out (actuator units).

    During the soft start ``ease = (start positions, elapsed s)`` blends the targets from
    where the actuators were (:func:`riderlive.platform.mechanism.limits.eased`) before the safety stage.
    """
    cue_state, target = aim(model, state.cueing, saddle, dt)
    targets: Sequence[float] = target.targets
    if ease is not None:
        targets = limits.eased(ease[0], target.targets, ease[1], model.soft_start_s)
    safety_state, positions = limits.step(model.safety, state.safety, targets, dt)
    scaled = state.scaled_back + (1 if target.scale < 1.0 else 0)
    return PlatformState(cue_state, safety_state, scaled), Frame(target, positions)


@dataclass(frozen=True, eq=False)
class Bake:
    """A whole take: per frame the pose aimed at (base frame, after the scale-back; the IK targets are
    its actuator positions), the kept share of the way from home, and the commands after the safety stage."""

    pose: FloatArray
    scale: FloatArray
    positions: FloatArray
    state: PlatformState


def bake(model: PlatformModel, saddle: FloatArray, dt: float | FloatArray, state: PlatformState | None = None) -> Bake:
    """Run a take of saddle poses (``(N, 6)``; ``dt`` one step or one per frame, s) through the platform.

    Works through the take in chunks of :data:`CHUNK` frames, each through all three stages,
    so the temporaries stay in the CPU cache and only the outputs touch new memory.
    """
    state = initial(model) if state is None else state
    u = np.ascontiguousarray(saddle, dtype=np.float64)
    if u.ndim != 2 or u.shape[1] != 6:
        raise ValueError(f"expected an (N, 6) saddle array, got {u.shape}")
    n, legs = u.shape[0], model.geometry.legs
    steps = np.broadcast_to(np.asarray(dt, dtype=np.float64), (n,))
    home = np.asarray(model.geometry.home)
    pose, scale, positions = np.empty((n, 6)), np.empty(n), np.empty((n, legs))
    cue_state, safety_state, scaled = state.cueing, state.safety, state.scaled_back
    for start in range(0, n, CHUNK):
        stop = min(start + CHUNK, n)
        cue_state, cue = cueing.run(model.cueing, cue_state, u[start:stop], steps[start:stop])
        cue += home
        q, lam = model.workspace.fit_batch(cue)
        out = np.flatnonzero(lam < 1.0)
        if out.size:
            cue[out] = home + lam[out, None] * (cue[out] - home)
            scaled += int(out.size)
        safety_state, positions[start:stop] = limits.run(model.safety, safety_state, q, steps[start:stop])
        pose[start:stop], scale[start:stop] = cue, lam
    return Bake(pose, scale, positions, PlatformState(cue_state, safety_state, scaled))
