"""The cueing's parameters (validated at load: ``[platform.cueing]``, ``PATCH /api/platform``)
and its shipped presets; the filters that use them are :mod:`riderlive.platform.mechanism.cueing`."""

from __future__ import annotations

from typing import Self

import pydantic
from pydantic import Field

from riderlive.configfile import StrictModel

Amplitudes = tuple[float, float, float, float, float, float]


class CueingParams(StrictModel):
    """Every cueing number (frequencies in Hz, times in s, angles in deg, rates in deg/s)."""

    preset: str = "standard"
    """The preset these values started from (informational)."""
    intensity: float = Field(100.0, ge=0.0, le=100.0)
    """Percent of the cue played: 0 holds the platform at home."""
    drift_cutoff_hz: float = Field(0.08, ge=0.01, le=0.5)
    """Replay: the tracker's cut-off while the cue fits (drift and offset removal)."""
    washout_translation_hz: float = Field(0.5, ge=0.1, le=2.5)
    washout_rotation_hz: float = Field(0.4, ge=0.1, le=2.5)
    washout_attack_s: float = Field(0.05, ge=0.005, le=1.0)
    washout_hold_s: float = Field(2.0, ge=0.0, le=10.0)
    washout_release_s: float = Field(0.5, ge=0.05, le=5.0)
    knee: float = Field(0.7, ge=0.2, le=0.95)
    """Share of an axis' room below which the cue is played unchanged."""
    share: float = Field(0.9, gt=0.0, le=1.0)
    """Share of an axis' single-axis reach the cue may use (the rest is left for the other axes)."""
    tilt_gain: float = Field(1.0, ge=0.0, le=1.0)
    tilt_cutoff_hz: float = Field(0.2, ge=0.05, le=1.0)
    tilt_rate_dps: float = Field(6.0, gt=0.0, le=60.0)
    tilt_max_deg: float = Field(10.0, ge=0.0, le=30.0)
    reference_amplitude: Amplitudes = (0.07, 0.12, 0.04, 2.5, 2.5, 11.0)
    """The largest gait swing per axis the automatic scale makes room for (m, deg; half peak to peak):
    the procedural horse's saddle at any gait and speed (canter heave 0.118 m, gallop pitch 11.1 deg)."""
    scale: Amplitudes | None = None
    """Explicit scale per axis (0-2) instead of the automatic one."""
    blend_s: float = Field(0.5, ge=0.0, le=10.0)
    """Time constant with which live changes take effect."""

    @pydantic.field_validator("reference_amplitude")
    @classmethod
    def _positive(cls, value: Amplitudes) -> Amplitudes:
        if not all(v > 0.0 for v in value):
            raise ValueError("every reference amplitude must be > 0")
        return value

    @pydantic.field_validator("scale")
    @classmethod
    def _scale_range(cls, value: Amplitudes | None) -> Amplitudes | None:
        if value is not None and not all(0.0 <= v <= 2.0 for v in value):
            raise ValueError("every scale must be within 0-2")
        return value

    @pydantic.model_validator(mode="after")
    def _order(self) -> Self:
        for name in ("washout_translation_hz", "washout_rotation_hz"):
            if getattr(self, name) <= self.drift_cutoff_hz:
                raise ValueError(f"{name} must be above drift_cutoff_hz ({self.drift_cutoff_hz:g})")
        return self


PRESETS: dict[str, CueingParams] = {
    "gentle": CueingParams(
        preset="gentle",
        intensity=70.0,
        washout_translation_hz=0.3,
        washout_rotation_hz=0.3,
        knee=0.6,
        tilt_cutoff_hz=0.15,
        tilt_rate_dps=3.0,
        tilt_max_deg=6.0,
    ),
    "standard": CueingParams(),
    "lively": CueingParams(
        preset="lively",
        washout_translation_hz=0.8,
        washout_rotation_hz=0.6,
        washout_hold_s=1.5,
        knee=0.8,
        share=0.95,
        tilt_cutoff_hz=0.3,
        tilt_rate_dps=12.0,
        tilt_max_deg=15.0,
    ),
}
"""Shipped presets: ``gentle`` (a first ride, therapy), ``standard``, ``lively`` (a seasoned rider)."""
