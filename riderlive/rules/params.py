"""Every weight, offset and limit of the rider rules, as a validated preset.

A preset is a TOML file with one table per rule group (see ``config/presets``).
``config/presets/kuhnel2003.toml`` holds the thesis' Appendix B values with the
readings of ``docs/rules.md`` (errata); ``kuhnel2003_literal.toml`` reproduces every
self-contradiction of Appendix B verbatim. Lengths are in the thesis rig's units,
angles in degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pydantic

from riderlive.configfile import CONFIG_DIR, StrictModel, load, read_toml, validate
from riderlive.names import check_name

PRESET_DIR = CONFIG_DIR / "presets"
"""The shipped presets (the repository's ``config/presets``)."""


class LowerBack(StrictModel):
    """Eq. 1-3: lower back forward/back (clamped by foot heights), side, twist."""

    pivot_height_offset: float = 2.0  # h1, added to the rear pivot's height
    pivot_weight: float = 0.07  # w1, rear pivot pitch x (height + h1)
    front_feet_weight: float = 0.25  # w2, front hooves' mean position (enters negated)
    back_feet_weight: float = 0.25  # w3, back hooves' mean position
    pivot_rotation_offset: float = 5.0  # h2, added to |pitch|
    pivot_rotation_weight: float = 0.1  # w4
    front_height_weight: float = 0.9  # w5
    back_height_weight: float = 0.4  # w6
    height_term_weight: float = 0.4  # w7
    front_height_limit: float = 18.0  # front hoof height sum used at most
    back_height_limit: float = 15.0  # back hoof height sum used at most
    side_gain: float = -1.0  # Eq. 2: against the horse's roll
    twist_gain: float = 0.5  # Eq. 3: twist toward the side lean


class Waist(StrictModel):
    """Eq. 4: the waist bends a little more than the lower back."""

    gain: float = 1.7


class Hip(StrictModel):
    """Eq. 5-6: hips follow the lower back and the horse's hips."""

    forward_gain: float = 0.8
    side_pivot_gain: float = 0.5
    side_rear_hoof_gain: float = 2.0


class Lift(StrictModel):
    """Eq. 7: lift out of the seat."""

    front_height_gain: float = 2.0  # w1
    gain: float = 0.01  # w2
    limit: float = 15.0


class SeatShift(StrictModel):
    """Eq. 8: shift forward/back in the saddle, within +-limit."""

    pivot_gain: float = 2.0
    gain: float = 0.1
    limit: float = pydantic.Field(default=1.0, ge=0.0)


class Squash(StrictModel):
    """Eq. 9: spine joints translate with a fraction of the lift."""

    rest_spine_c: float = 0.482
    rest_spine_d: float = 0.564
    rest_spine_f: float = 0.949
    rest_neck: float = 1.392
    rest_head_a: float = 1.002
    offset: float = 0.1  # h1: start a little squashed
    spine_divisor: float = 6.0
    neck_divisor: float = 7.0

    @pydantic.field_validator("spine_divisor", "neck_divisor")
    @classmethod
    def _nonzero(cls, value: float) -> float:
        if value == 0.0:
            raise ValueError("must not be zero")
        return value


class Head(StrictModel):
    """Eq. 10-11: the head counters the lower back and the lift."""

    back_gain: float = 0.9
    lift_gain: float = 18.0
    offset: float = 5.0  # head starts 5 degrees down
    back_max: float = 17.0  # lower back used at most
    back_min: float = -20.0  # lower back used at least
    side_gain: float = 0.8  # Eq. 11 per Appendix B (section 8 writes -1)


class Wrists(StrictModel):
    """Eq. 12-13: wrists forward/back and up/down."""

    back_gain: float = 0.0001
    pivot_gain: float = 0.008
    back_limit: float = 17.0
    height_gain: float = 0.03
    height_limit: float = 20.0
    pivot_height_gain: float = 0.0005


class Feet(StrictModel):
    """Eq. 14-17: feet forward/back, pitch, side, twist, toward the belly."""

    height_limit: float = 15.0
    side_gain: float = -1.7  # ry per hoof height
    side_offset: float = -1.0
    twist_gain: float = 0.1  # rx per hoof height, right foot negated
    twist_offset: float = 1.0
    belly_gain: float = -0.05
    belly_offset: float = 2.0
    belly_pivot_gain: float = 0.05
    forward_pivot_gain: float = 0.005
    forward_offset: float = 0.08  # Eq. 14's h1 (section 8 writes 0.8)
    forward_back_mid_gain: float = 0.02
    forward_back_gain: float = 0.005
    pitch_offset: float = 3.0
    pitch_scale: float = -6.0
    pitch_gain: float = 2.0


class Knees(StrictModel):
    """Eq. 18 and the knee lift."""

    rest_tz: float = 0.0  # the "initial position": 0 = output is relative to the rig's rest
    belly_gain: float = 1.1
    lift_gain: float = 0.03
    lift_offset: float = -1.0


class HairCloth(StrictModel):
    """The hair and cloth attributes of Appendix B."""

    height_offset: float = -2.0
    hair_up_gain: float = 0.7
    hair_side_gain: float = -0.02
    cloth_up_gain: float = 0.7
    cloth_side_pivot_gain: float = -0.5
    cloth_side_rear_hoof_gain: float = -2.0


class Smoothing(StrictModel):
    """Optional output filter of the animator layer; 0 s = off (the thesis)."""

    time_constant: float = pydantic.Field(default=0.0, ge=0.0, le=10.0)  # seconds


class Reins(StrictModel):
    """Section 5.1: the hands hold the reins close to the horse's neck and follow its mouth.

    Each hand keeps its rest distance to its bit ring (times ``length_scale``) along the
    line from the ring to where the seat carries the hand; Eq. 12-13 (the wrists) add on
    top. ``weight`` 0 gives the hands of Appendix B alone (offsets from the seat).
    """

    weight: float = pydantic.Field(default=1.0, ge=0.0, le=1.0)
    length_scale: float = pydantic.Field(default=1.0, ge=0.5, le=2.0)  # rein length / the skeletons' rest length
    reach: float = pydantic.Field(default=0.97, ge=0.5, le=1.0)  # longest shoulder-to-hand, fraction of the arm


class Arms(StrictModel):
    """Section 5.3: the arms come in to the body as the rider rises and go out as she comes down."""

    in_gain: float = pydantic.Field(default=0.6, ge=-10.0, le=10.0)  # elbow in per unit of lift (Eq. 7)


class Stirrups(StrictModel):
    """The feet stand in the stirrups: the ball of each foot stays within a leather's length of its bar."""

    weight: float = pydantic.Field(default=1.0, ge=0.0, le=1.0)  # 0: the feet of Appendix B alone
    leather_scale: float = pydantic.Field(default=1.0, ge=0.5, le=1.5)  # leather / the skeletons' rest length


class FollowThrough(StrictModel):
    """Section 9.3's loosening: an underdamped spring per rider channel, after the smoothing.

    ``frequency``: natural frequency, Hz (0 = off, the thesis); ``damping_ratio`` below 1:
    a step overshoots by ``exp(-pi z / sqrt(1 - z^2))`` (0.4: 25 %).
    """

    frequency: float = pydantic.Field(default=0.0, ge=0.0, le=20.0)
    damping_ratio: float = pydantic.Field(default=0.4, ge=0.05, le=0.95)


class Terrain(StrictModel):
    """Section 10: the rider's own answer to sloping ground (``riderlive.rules.terrain``).

    The rules read the horse relative to the ground; then ``lower_back.rz`` gets
    ``(upright + lean) * ground.rz``, ``lean`` = ``uphill_lean`` on a rise (+ forward)
    and ``downhill_lean`` on a descent (the product is then negative: back). With
    ``upright`` 1 the rider's trunk keeps its flat-ground attitude in the world (the
    horse's pitch by the ground taken out), plus the lean; 0 tilts her with the horse.
    """

    upright: float = pydantic.Field(default=1.0, ge=0.0, le=1.0)
    uphill_lean: float = pydantic.Field(default=0.5, ge=0.0, le=1.0)  # deg forward per deg of rise
    downhill_lean: float = pydantic.Field(default=0.1, ge=0.0, le=1.0)  # deg back per deg of descent


class Jump(StrictModel):
    """Over a fence, what Appendix B leaves out (``riderlive.rules.jump``; ``weight`` 0: Appendix B).

    While the horse's forehand rises (its pitch beyond any gait's, not from the hindquarters sitting
    down as in a sliding stop; or the front hooves higher than a gallop lifts them) the trunk folds
    forward from the hip to ``fold`` degrees forward of upright in the world; while only the hind
    hooves are high (landing, a buck) it opens to ``land`` degrees (- back). Its bend against the
    horse's back stays within ``max_bend``.
    """

    weight: float = pydantic.Field(default=1.0, ge=0.0, le=1.0)
    fold: float = pydantic.Field(default=30.0, ge=0.0, le=60.0)  # deg forward of upright, world
    land: float = pydantic.Field(default=-5.0, ge=-30.0, le=10.0)  # deg, - behind upright, world
    max_bend: float = pydantic.Field(default=60.0, ge=10.0, le=90.0)  # deg, trunk against the horse's back
    hip_share: float = pydantic.Field(default=0.6, ge=0.0, le=1.0)  # of the bend at the hip; the rest the back
    head_follow: float = pydantic.Field(default=0.9, ge=0.0, le=1.0)  # head counters this much of the lean
    pitch_from: float = pydantic.Field(default=8.0, ge=0.0, le=45.0)  # deg, rearPivot.rz: none below (gaits 7)
    pitch_full: float = pydantic.Field(default=16.0, ge=1.0, le=60.0)  # deg: fully folded from here
    sit_from: float = pydantic.Field(default=2.5, ge=0.0, le=50.0)  # thesis units the hindquarters sink: a stop
    sit_full: float = pydantic.Field(default=4.0, ge=0.1, le=50.0)  # (a take-off sinks 2, a sliding stop 8)
    hooves_from: float = pydantic.Field(default=16.0, ge=0.0, le=100.0)  # thesis units, a pair's height sum
    hooves_full: float = pydantic.Field(default=36.0, ge=1.0, le=200.0)  # (a gallop lifts a pair to 14)

    @pydantic.model_validator(mode="after")
    def _ordered(self) -> Jump:
        if self.pitch_full <= self.pitch_from or self.hooves_full <= self.hooves_from or self.sit_full <= self.sit_from:
            raise ValueError("jump: each *_full must exceed its *_from (pitch, sit, hooves)")
        return self


class Errata(StrictModel):
    """Where Appendix B contradicts itself: numbers that select a reading.

    The defaults are the readings chosen in ``docs/rules.md``; the literal
    Appendix B values are given in each comment.
    """

    front_clamped_lf_tx_offset: float = 0.0  # literal 2.5 (Eq. 1, second branch)
    wrist_clamped_sign: float = pydantic.Field(default=1.0, ge=-1.0, le=1.0)  # literal -1
    pivot_rest_offset: float = 0.0  # literal 0.572 (Eq. 12 and 14, one branch each)
    seat_shift_test_back_gain: float = 1.0  # literal 1.7 (test uses the waist)
    left_foot_clamped_sign: float = pydantic.Field(default=1.0, ge=-1.0, le=1.0)  # literal -1
    left_foot_clamped_belly_pivot_gain: float = 0.05  # literal 0.02
    waist_side_from_lower_back: float = 1.0  # literal 0: waist.ry is never assigned
    right_knee_from_left_foot: float = pydantic.Field(default=0.0, ge=0.0, le=1.0)  # literal 1


class RuleParams(StrictModel):
    """A complete preset. Unset keys keep the thesis values."""

    name: str = "kuhnel2003"
    description: str = ""
    lower_back: LowerBack = LowerBack()
    waist: Waist = Waist()
    hip: Hip = Hip()
    lift: Lift = Lift()
    seat_shift: SeatShift = SeatShift()
    squash: Squash = Squash()
    head: Head = Head()
    wrists: Wrists = Wrists()
    feet: Feet = Feet()
    knees: Knees = Knees()
    hair_cloth: HairCloth = HairCloth()
    smoothing: Smoothing = Smoothing()
    errata: Errata = Errata()
    reins: Reins = Reins()
    arms: Arms = Arms()
    stirrups: Stirrups = Stirrups()
    follow_through: FollowThrough = FollowThrough()
    terrain: Terrain = Terrain()
    jump: Jump = Jump()

    def with_values(self, changes: dict[str, float]) -> RuleParams:
        """Return a copy with dotted keys (``"head.lift_gain"``) changed, validated."""
        data: dict[str, Any] = self.model_dump()
        for dotted, value in changes.items():
            group, _, key = dotted.partition(".")
            if group not in data or not isinstance(data[group], dict) or key not in data[group]:
                raise KeyError(f"unknown rule parameter {dotted!r}")
            data[group][key] = value
        return validate(RuleParams, data, f"preset {self.name!r}")

    def flat(self) -> dict[str, float]:
        """All numeric parameters as ``{"group.key": value}``."""
        out: dict[str, float] = {}
        for group, table in self.model_dump().items():
            if isinstance(table, dict):
                out.update({f"{group}.{k}": float(v) for k, v in table.items()})
        return out


def load_preset(name_or_path: str | Path) -> RuleParams:
    """Load a preset by file path or by the name of a shipped preset."""
    path = Path(name_or_path)
    if not path.suffix and not path.exists():
        path = PRESET_DIR / f"{name_or_path}.toml"
    params = load(RuleParams, path)
    if "name" not in read_toml(path):
        params = params.model_copy(update={"name": path.stem})
    return params


def find_preset(name: str, directories: Sequence[Path] = ()) -> Path | None:
    """The file of preset ``name`` (a name, never a path) in ``directories``, then the shipped ones."""
    check_name(name, "preset")
    for directory in (*directories, PRESET_DIR):
        path = directory / f"{name}.toml"
        if path.is_file():
            return path
    return None


def shipped_presets(directories: Sequence[Path] = ()) -> list[str]:
    """Names of the presets in ``directories`` and shipped with the package."""
    names = {p.stem for d in (*directories, PRESET_DIR) for p in d.glob("*.toml") if not p.name.startswith(".")}
    return sorted(n for n in names if find_preset(n, directories) is not None)
