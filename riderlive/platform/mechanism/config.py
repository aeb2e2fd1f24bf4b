"""Platform files: ``config/platforms/NAME.toml``, validated at load into a :class:`Geometry`.

A file names its ``kind`` (``stewart_linear``, ``stewart_rotary``,
``heave_pitch_roll``), what it carries, its ``[joints]`` (a hexagon by radii and pair
spreads, or explicit ``base`` and ``platform`` joint lists), its ``[actuators]``
(stroke or arm limits, soft margins, per-actuator ``max_speed`` and ``max_accel``),
the ``[home]`` and ``[park]`` poses of the platform's origin, the ``[centre]`` the cue
turns about, the soft start and park times, and a ``[cueing]`` table (a ``preset``
plus any overrides of :class:`~riderlive.platform.mechanism.cueing_params.CueingParams`). See
``docs/platform.md``.

Beyond the schema (unknown keys, ranges), :func:`platform_problems` refuses what cannot
be driven safely: limits in the wrong order, a home or park pose outside the soft
limits (naming the actuator and by how much), a home with no room on some axis, and a
soft start or park too short for a full stroke within the speed and acceleration
limits, and limits so slow that the firmware's dead-man park over a full stroke would
outlast ``link_vocab.PARK_BOUND_S`` (the firmware refuses such a CONFIG). Every error names the
file and the key.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal, Self

import pydantic
from pydantic import Field

from riderlive.configfile import CONFIG_DIR, ConfigError, StrictModel, read_toml, validate
from riderlive.platform.link_vocab import PARK_BOUND_S, PARK_SCALE, firmware_park_s
from riderlive.platform.mechanism.cueing_params import PRESETS, CueingParams
from riderlive.platform.mechanism.geometry import Geometry, Kind, Pose, Vec3, hexagon, rotation, tangential_arms
from riderlive.platform.mechanism.ik import SCALAR, axis_ranges, make_ik
from riderlive.platform.mechanism.limits import ease_seconds

PLATFORM_DIR = CONFIG_DIR / "platforms"
"""The shipped platform files (the repository's ``config/platforms``)."""
MIN_ROOM = (0.001, 0.001, 0.001, 0.1, 0.1, 0.1)
"""Every axis the mechanism moves must reach at least this far both ways from home (m, deg)."""

Triple = tuple[float, float, float]


class PoseConfig(StrictModel):
    """A pose of the platform's origin in the base frame (m, deg)."""

    tx: float = Field(0.0, ge=-5.0, le=5.0)
    ty: float = Field(0.0, ge=-5.0, le=5.0)
    tz: float = Field(0.0, ge=-5.0, le=5.0)
    rx: float = Field(0.0, ge=-90.0, le=90.0)
    ry: float = Field(0.0, ge=-90.0, le=90.0)
    rz: float = Field(0.0, ge=-90.0, le=90.0)

    def values(self) -> Pose:
        return (self.tx, self.ty, self.tz, self.rx, self.ry, self.rz)


class PointConfig(StrictModel):
    """A point in the platform frame, from the platform's origin (m)."""

    tx: float = Field(0.0, ge=-5.0, le=5.0)
    ty: float = Field(0.0, ge=-5.0, le=5.0)
    tz: float = Field(0.0, ge=-5.0, le=5.0)


class JointsConfig(StrictModel):
    """A hexagon (radii in m, pair spreads in deg) or explicit joint lists (``[x, y, z]`` in m)."""

    base_radius: float | None = Field(None, gt=0.0, le=10.0)
    base_spread_deg: float | None = Field(None, ge=0.0, lt=120.0)
    platform_radius: float | None = Field(None, gt=0.0, le=10.0)
    platform_spread_deg: float | None = Field(None, ge=0.0, lt=120.0)
    base: list[Triple] | None = None
    platform: list[Triple] | None = None

    @pydantic.model_validator(mode="after")
    def _one_form(self) -> Self:
        radii = (self.base_radius, self.base_spread_deg, self.platform_radius, self.platform_spread_deg)
        lists = (self.base, self.platform)
        if all(v is not None for v in radii) and all(v is None for v in lists):
            return self
        if all(v is None for v in radii) and all(v is not None for v in lists):
            return self
        raise ValueError(
            "give base_radius, base_spread_deg, platform_radius and platform_spread_deg (a hexagon), "
            "or base and platform (joint lists), not a mix"
        )


class ActuatorsConfig(StrictModel):
    """Linear: lengths joint to joint (m), speeds in m/s. Rotary: arm and rod (m), angles (deg), deg/s."""

    min_length: float | None = Field(None, gt=0.0, le=10.0)
    max_length: float | None = Field(None, gt=0.0, le=10.0)
    soft_margin: float | None = Field(None, ge=0.0, le=0.5)
    arm_length: float | None = Field(None, gt=0.0, le=2.0)
    rod_length: float | None = Field(None, gt=0.0, le=5.0)
    min_angle_deg: float | None = Field(None, ge=-90.0, le=90.0)
    max_angle_deg: float | None = Field(None, ge=-90.0, le=90.0)
    soft_margin_deg: float | None = Field(None, ge=0.0, le=30.0)
    max_speed: float | list[float]
    """Per actuator, or one value for all (m/s or deg/s)."""
    max_accel: float | list[float]
    """Per actuator, or one value for all (m/s^2 or deg/s^2)."""

    @pydantic.field_validator("max_speed", "max_accel")
    @classmethod
    def _positive(cls, value: float | list[float]) -> float | list[float]:
        values = value if isinstance(value, list) else [value]
        if not all(math.isfinite(v) and v > 0.0 for v in values):
            raise ValueError("must be > 0 (one number, or one per actuator)")
        return value


LINEAR_KEYS = ("min_length", "max_length", "soft_margin")
ROTARY_KEYS = ("arm_length", "rod_length", "min_angle_deg", "max_angle_deg", "soft_margin_deg")


class PlatformConfig(StrictModel):
    """A whole platform file."""

    name: str
    description: str = ""
    kind: Kind
    carries: Literal["person", "puppet"]
    """What the platform is built to carry: a person in a saddle, or the rider puppet."""
    payload_kg: float = Field(gt=0.0, le=1000.0)
    joints: JointsConfig
    actuators: ActuatorsConfig
    home: PoseConfig
    park: PoseConfig
    centre: PointConfig = Field(default_factory=PointConfig)
    """The point the cue turns about, in the platform frame (the saddle's seat)."""
    soft_start_s: float = Field(3.0, ge=1.0, le=5.0)
    park_s: float = Field(3.0, ge=1.0, le=5.0)
    cueing: CueingParams = Field(default_factory=CueingParams)

    @pydantic.field_validator("cueing", mode="before")
    @classmethod
    def _preset(cls, value: Any) -> Any:
        if isinstance(value, dict):
            name = value.get("preset", "standard")
            if name not in PRESETS:
                raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
            return {**PRESETS[name].model_dump(), **value}
        return value


def _per_actuator(value: float | list[float], legs: int) -> tuple[float, ...]:
    return tuple(value) if isinstance(value, list) else (value,) * legs


def _joint_lists(cfg: PlatformConfig) -> tuple[tuple[Vec3, ...], tuple[Vec3, ...]]:
    j = cfg.joints
    if j.base is not None and j.platform is not None:
        return tuple(j.base), tuple(j.platform)
    assert j.base_radius and j.platform_radius and j.base_spread_deg is not None and j.platform_spread_deg is not None
    return hexagon(j.base_radius, j.base_spread_deg, j.platform_radius, j.platform_spread_deg)


def _centre_pose(origin: Pose, centre: Vec3) -> Pose:
    r = rotation(origin[3], origin[4], origin[5])
    return (
        origin[0] + r[0][0] * centre[0] + r[0][1] * centre[1] + r[0][2] * centre[2],
        origin[1] + r[1][0] * centre[0] + r[1][1] * centre[1] + r[1][2] * centre[2],
        origin[2] + r[2][0] * centre[0] + r[2][1] * centre[1] + r[2][2] * centre[2],
        origin[3],
        origin[4],
        origin[5],
    )


def _structure_problems(cfg: PlatformConfig) -> list[tuple[str, str]]:
    """Problems that stop a Geometry from being built at all."""
    kind, a = cfg.kind, cfg.actuators
    legs = kind.legs
    problems: list[tuple[str, str]] = []
    if cfg.joints.base is None and legs != 6:
        problems.append(("joints", f"a {kind.value} platform lists its {legs} joints as base and platform"))
    for name in ("base", "platform"):
        joints = getattr(cfg.joints, name)
        if joints is not None and len(joints) != legs:
            problems.append((f"joints.{name}", f"a {kind.value} platform has {legs} joints, got {len(joints)}"))
    needed, unused = (ROTARY_KEYS[:4], LINEAR_KEYS) if kind.rotary else (LINEAR_KEYS[:2], ROTARY_KEYS)
    for key in needed:
        if getattr(a, key) is None:
            problems.append((f"actuators.{key}", f"required for a {kind.value} platform"))
    for key in unused:
        if getattr(a, key) is not None:
            problems.append((f"actuators.{key}", f"not used by a {kind.value} platform"))
    for key in ("max_speed", "max_accel"):
        value = getattr(a, key)
        if isinstance(value, list) and len(value) != legs:
            problems.append((f"actuators.{key}", f"one value or {legs} (one per actuator), got {len(value)}"))
    if not problems and kind.rotary:
        assert a.min_angle_deg is not None and a.max_angle_deg is not None and a.arm_length and a.rod_length
        margin = 2.0 if a.soft_margin_deg is None else a.soft_margin_deg
        if a.max_angle_deg <= a.min_angle_deg:
            problems.append(("actuators.max_angle_deg", f"must be above min_angle_deg ({a.min_angle_deg:g})"))
        elif 2.0 * margin >= a.max_angle_deg - a.min_angle_deg:
            problems.append(("actuators.soft_margin_deg", "leaves no room between the soft limits"))
        if a.rod_length <= a.arm_length:
            problems.append(("actuators.rod_length", f"must be longer than arm_length ({a.arm_length:g})"))
    elif not problems:
        assert a.min_length is not None and a.max_length is not None
        margin = 0.005 if a.soft_margin is None else a.soft_margin
        if a.max_length <= a.min_length:
            problems.append(("actuators.max_length", f"must be above min_length ({a.min_length:g})"))
        elif 2.0 * margin >= a.max_length - a.min_length:
            problems.append(("actuators.soft_margin", "leaves no room between the soft limits"))
    if not kind.axes[0]:
        fixed = [f"{pose}.{axis}" for pose in ("home", "park") for axis in ("tx", "tz", "ry")]
        fixed = [key for key in fixed if getattr(getattr(cfg, key.split(".")[0]), key.split(".")[1]) != 0.0]
        problems.extend((key, f"a {kind.value} rig's guide holds it at 0") for key in fixed)
        if cfg.centre != PointConfig():
            problems.append(("centre", f"a {kind.value} rig turns about its guide's pivot: leave centre at 0"))
    return problems


def build_geometry(cfg: PlatformConfig) -> Geometry:
    """The numbers of a validated platform file (no reachability checks; see :func:`platform_problems`)."""
    legs = cfg.kind.legs
    a = cfg.actuators
    base, joints = _joint_lists(cfg)
    centre = (cfg.centre.tx, cfg.centre.ty, cfg.centre.tz)
    platform = tuple((p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]) for p in joints)
    common: dict[str, Any] = {
        "kind": cfg.kind,
        "base": base,
        "platform": platform,
        "max_speed": _per_actuator(a.max_speed, legs),
        "max_accel": _per_actuator(a.max_accel, legs),
        "home": _centre_pose(cfg.home.values(), centre),
        "park": _centre_pose(cfg.park.values(), centre),
        "centre": centre,
    }
    if cfg.kind.rotary:
        assert a.min_angle_deg is not None and a.max_angle_deg is not None and a.arm_length and a.rod_length
        margin = 2.0 if a.soft_margin_deg is None else a.soft_margin_deg
        lo, hi = a.min_angle_deg, a.max_angle_deg
        return Geometry(
            **common,
            lower=(lo + margin,) * legs,
            upper=(hi - margin,) * legs,
            hard_lower=(lo,) * legs,
            hard_upper=(hi,) * legs,
            arm=a.arm_length,
            rod=a.rod_length,
            arm_direction=tangential_arms(base),
        )
    assert a.min_length is not None and a.max_length is not None
    margin = 0.005 if a.soft_margin is None else a.soft_margin
    stroke = a.max_length - a.min_length
    return Geometry(
        **common,
        lower=(margin,) * legs,
        upper=(stroke - margin,) * legs,
        hard_lower=(0.0,) * legs,
        hard_upper=(stroke,) * legs,
        min_length=a.min_length,
    )


def _pose_problems(g: Geometry, key: str, pose: Pose) -> list[tuple[str, str]]:
    q, reach = make_ik(g, SCALAR)(*pose)
    unit = g.unit
    if reach < 0.0:
        return [(key, "the platform cannot reach this pose: a rod is too short for its arm's circle")]
    problems = []
    for i, (qi, lo, hi) in enumerate(zip(q, g.lower, g.upper, strict=True)):
        if not lo <= qi <= hi:
            side = f"{lo - qi:.4g} {unit} below" if qi < lo else f"{qi - hi:.4g} {unit} above"
            problems.append(
                (
                    key,
                    f"the platform cannot reach this pose: actuator {i + 1} needs {qi:.4g} {unit}, {side} "
                    f"its soft range {lo:.4g} .. {hi:.4g} {unit}",
                )
            )
    return problems[:1]


def platform_problems(cfg: PlatformConfig) -> list[tuple[str, str]]:
    """Every reason ``cfg`` cannot be driven safely, as (key, message) pairs."""
    problems = _structure_problems(cfg)
    if problems:
        return problems
    g = build_geometry(cfg)
    problems = _pose_problems(g, "home", g.home) + _pose_problems(g, "park", g.park)
    if problems:
        return problems
    for axis, ((down, up), free, least) in enumerate(zip(axis_ranges(g), cfg.kind.axes, MIN_ROOM, strict=True)):
        name = ("tx", "ty", "tz", "rx", "ry", "rz")[axis]
        if free and min(down, up) < least:
            problems.append(("home", f"leaves no room on {name}: it reaches -{down:.4g} / +{up:.4g} from home"))
    span = [hi - lo for lo, hi in zip(g.lower, g.upper, strict=True)]
    need = ease_seconds([0.0] * g.legs, span, g.max_speed, g.max_accel)
    for key in ("soft_start_s", "park_s"):
        if getattr(cfg, key) < need:
            problems.append(
                (
                    key,
                    f"{getattr(cfg, key):g} s is too short for a full stroke within max_speed and max_accel "
                    f"(needs >= {need:.2f} s)",
                )
            )
    firmware_park = max(map(firmware_park_s, span, g.max_speed, g.max_accel))
    if firmware_park > PARK_BOUND_S:  # the firmware refuses such limits: docs/platform-link.md
        problems.append(
            (
                "actuators.max_speed",
                f"too slow for the firmware's dead-man park: at {PARK_SCALE:.0%} of max_speed over a full "
                f"stroke it takes {firmware_park:.2f} s, at most {PARK_BOUND_S:g} s (raise max_speed or max_accel)",
            )
        )
    return problems


def platform_from_dict(data: Any, source: str = "<platform>") -> PlatformConfig:
    """Validate an already-parsed platform file; every error names ``source`` and the key."""
    cfg = validate(PlatformConfig, data, source)
    problems = platform_problems(cfg)
    if problems:
        key, message = problems[0]
        raise ConfigError(source, key, message)
    return cfg


def load_platform(path: str | Path) -> PlatformConfig:
    """Read and validate a platform file; a bare name is looked up in ``config/platforms``."""
    path = Path(path)
    if not path.suffix and not path.exists():
        path = PLATFORM_DIR / f"{path}.toml"
    return platform_from_dict(read_toml(path), str(path))


def shipped_platforms() -> list[str]:
    return sorted(p.stem for p in PLATFORM_DIR.glob("*.toml"))
