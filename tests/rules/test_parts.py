"""The rider parts: hands on the reins (5.1), arms in the gallop (5.3), feet in the stirrups.

The reins and stirrups are checked against the skeletons themselves: the parts compute
their channels, the rider and horse skeletons are posed from them (``riderlive.skeleton``,
the path engines and the page use), and the posed hand must sit on its rein, the posed
ankle within its leather.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive import fastpath
from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER, RIDER_INDEX, RIDER_NAMES, RIDER_PART_NAMES, Kind
from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.ranges import DEFAULT_RANGES
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams, load_preset
from riderlive.rules.parts import KNOBS, PartsGeometry, RiderParts, default_geometry, parts_knobs
from riderlive.skeleton import HORSE_RIG, horse_pose, quat, rider_pose, rider_rig
from riderlive.skeleton.rig import Rig, bones_from_rows

THESIS = load_preset("kuhnel2003")
MODEL = RiderModel(THESIS, scale=DEFAULT_SCALE)
PARTS = RiderParts(THESIS)
PART = {n: i for i, n in enumerate(RIDER_PART_NAMES)}


def horse(**values: float) -> list[float]:
    frame = [0.0] * len(HORSE_NAMES)
    for key, value in values.items():
        frame[HORSE_INDEX[key.replace("_", ".", 1)]] = value
    return frame


def posed(horse_frame: list[float], rider: list[float] | None = None, parts: RiderParts = PARTS) -> tuple:
    """Rider frame, parts and the rider's world joint positions (seat frame) by bone name."""
    rider = MODEL.evaluate(horse_frame) if rider is None else rider
    values = parts.evaluate(horse_frame, rider)
    pose = rider_pose({**dict(zip(RIDER_NAMES, rider)), **dict(zip(RIDER_PART_NAMES, values))}, tack=True)
    return rider, values, dict(zip(rider_rig().names, pose.world_positions))


def in_seat_frame(horse_frame: list[float], bone: str) -> quat.Vec3:
    """A horse bone's position in the frame of the horse's saddle (the rider's origin and axes)."""
    pose = horse_pose(horse_frame)
    names = HORSE_RIG.names
    saddle = names.index("saddle")
    world = pose.world_positions[names.index(bone)]
    return quat.rotate(quat.conj(pose.world_rotations[saddle]), quat.sub(world, pose.world_positions[saddle]))


def wrist_delta(rider: list[float], side: str) -> quat.Vec3:
    neutral = rider_rig().neutral
    return (
        rider[RIDER_INDEX[f"{side}_wrist.tz"]] - neutral[f"{side}_wrist.tz"],
        rider[RIDER_INDEX[f"{side}_wrist.ty"]] - neutral[f"{side}_wrist.ty"],
        0.0,
    )


REST_HAND = rider_pose(MODEL.evaluate(horse())).world_positions[rider_rig().index["lf_hand"]]
REST_REIN = quat.norm(quat.sub(REST_HAND, in_seat_frame(horse(), "leftRein")))


def test_standing_horse_leaves_the_rest_pose_alone() -> None:
    _, values, _ = posed(horse())
    assert max(abs(v) for v in values) < 1e-12
    assert 0.9 < REST_REIN < 1.4  # a rein from the hands at the withers to the mouth, metres


@pytest.mark.parametrize(
    ("neck", "side", "head", "lift"),
    [(-20.0, 0.0, -10.0, 0.0), (12.0, 0.0, 8.0, 0.0), (-8.0, 9.0, -5.0, 0.0), (5.0, -7.0, 0.0, 0.0), (-15, 4, -6, 3.0)],
)
def test_each_posed_hand_keeps_its_rein_to_the_bit(neck: float, side: float, head: float, lift: float) -> None:
    """5.1: the hands stay on the reins; the grip (the posed hand less Eq. 12-13) keeps its rein's length."""
    frame = horse(horseNeck_rz=neck, horseNeck_ry=side, horseHead_rz=head, lfHoof_ty=lift / 25, rfHoof_ty=lift / 25)
    rider, values, joints = posed(frame)
    assert values[PART["reins.slip"]] == 0.0
    for s, ring in (("lf", "leftRein"), ("rt", "rightRein")):
        grip = quat.sub(joints[f"{s}_hand"], wrist_delta(rider, s))
        assert quat.norm(quat.sub(grip, in_seat_frame(frame, ring))) == pytest.approx(REST_REIN, abs=1e-9)


def test_hands_follow_the_mouth_forward_and_down_when_the_head_drops() -> None:
    _, values, _ = posed(horse(horseNeck_rz=-25.0, horseHead_rz=-10.0))
    assert values[PART["lf_rein.tx"]] > 0.02 and values[PART["lf_rein.ty"]] < -0.01
    assert values[PART["lf_rein.tz"]] == pytest.approx(-values[PART["rt_rein.tz"]], abs=1e-12)  # mirrored


@pytest.mark.parametrize("gait", ["walk", "trot", "canter"])
def test_hands_mostly_stay_in_position_through_a_gait(gait: str) -> None:
    """5.1: "her hands move a little about the horse's neck ... but mostly stay in position"."""
    take = generate_gait(gait, 3.0, 60.0)
    rider = MODEL.evaluate_batch(take.values)
    values = PARTS.evaluate_batch(take.values, rider)
    rein = values[:, [PART["lf_rein.tx"], PART["lf_rein.ty"], PART["lf_rein.tz"]]]
    spread = np.ptp(rein, axis=0)
    assert spread.max() < 0.06 and spread.max() > 0.002  # metres: a little, never nothing
    assert not values[:, PART["reins.slip"]].any()


def test_unreachable_reins_leave_the_hands_at_full_reach_and_say_so() -> None:
    frame = horse(horseNeck_rz=-70.0, horseHead_rz=60.0)  # neck to the ground, nose stretched out: no rein reaches
    _, values, joints = posed(frame)
    assert values[PART["reins.slip"]] > 0.05
    arm = default_geometry().arm_length
    reach = quat.norm(quat.sub(joints["lf_hand"], joints["lf_upperarm"]))
    assert reach == pytest.approx(THESIS.reins.reach * arm, rel=0.05)  # the shoulder is approximate
    assert reach <= arm + 1e-9


def test_gallop_arms_come_in_as_the_rider_rises_and_go_out_as_she_falls() -> None:
    """5.3: arms slightly into the body as she rises, slightly out as she falls back."""
    take = generate_gait("gallop", 2.0, 120.0)
    rider = MODEL.evaluate_batch(take.values)
    values = PARTS.evaluate_batch(take.values, rider)
    lift = rider[:, RIDER_INDEX["cog.ty"]]
    arm = values[:, PART["lf_arm.tz"]]
    rising, moving_in = np.diff(lift), np.diff(arm)
    big = np.abs(rising) > 1e-4
    assert big.sum() > 50 and np.all(np.sign(moving_in[big]) == -np.sign(rising[big]))
    top, bottom = int(np.argmax(lift)), int(np.argmin(lift))
    elbow = [abs(posed(list(take.values[i]), list(rider[i]))[2]["lf_forearm"][2]) for i in (top, bottom)]
    assert elbow[0] < elbow[1]  # the left elbow (z < 0) is nearer the body at the top of the flight


def test_feet_stay_within_their_leathers_and_swing_up_as_they_move() -> None:
    geo = default_geometry()
    assert geo.ankles is not None
    rng = np.random.default_rng(3)
    base = MODEL.evaluate(horse())
    for _ in range(40):
        rider = list(base)
        for s in ("lf", "rt"):
            rider[RIDER_INDEX[f"{s}_foot.tx"]] += rng.uniform(-0.15, 0.15)
            rider[RIDER_INDEX[f"{s}_foot.tz"]] += rng.uniform(-0.08, 0.12)
        _, values, joints = posed(horse(), rider)
        for k, s in enumerate(("lf", "rt")):
            d = quat.norm(quat.sub(joints[f"{s}_foot"], geo.centres[k]))
            correction = [values[PART[f"{s}_stirrup.{a}"]] for a in ("tx", "ty", "tz")]
            if any(correction):
                assert d == pytest.approx(geo.leathers[k], abs=1e-9)  # held at the leather's length
            else:
                assert d <= geo.leathers[k] + 1e-9  # free inside it
    forward = list(base)
    forward[RIDER_INDEX["lf_foot.tx"]] += 0.1  # Eq. 14 moves the foot forward: the iron swings up
    values = PARTS.evaluate(horse(), forward)
    assert values[PART["lf_stirrup.ty"]] > 0.005 and values[PART["lf_stirrup.tx"]] < 0.0


def test_the_stirrup_irons_hang_where_the_rest_feet_are() -> None:
    joints = dict(zip(rider_rig().names, rider_pose(MODEL.evaluate(horse())).world_positions))
    for s, iron in (("lf", "leftStirrup"), ("rt", "rightStirrup")):
        assert quat.norm(quat.sub(joints[f"{s}_toes"], in_seat_frame(horse(), iron))) < 1e-9


def test_appendix_b_alone_has_no_parts_and_weights_blend() -> None:
    off = {"reins.weight": 0.0, "stirrups.weight": 0.0, "arms.in_gain": 0.0}
    literal = RiderParts(THESIS.with_values(off))
    frame = horse(horseNeck_rz=-25.0, lfHoof_ty=0.2)
    assert literal.evaluate(frame, MODEL.evaluate(frame)) == [0.0] * len(RIDER_PART_NAMES)
    half = RiderParts(THESIS.with_values({"reins.weight": 0.5}))
    full_values = PARTS.evaluate(frame, MODEL.evaluate(frame))
    half_values = half.evaluate(frame, MODEL.evaluate(frame))
    assert half_values[PART["lf_rein.tx"]] == pytest.approx(0.5 * full_values[PART["lf_rein.tx"]], rel=1e-12)


def rows_without(*names: str, longer: dict[str, float] | None = None) -> Rig:
    """The default horse rig rebuilt without some bones (and with some offsets stretched)."""
    rows = []
    for bone in HORSE_RIG.bones:
        if bone.name in names:
            continue
        parent = None if bone.parent < 0 else HORSE_RIG.bones[bone.parent].name
        offset = quat.scale(bone.offset, (longer or {}).get(bone.name, 1.0))
        rows.append((bone.name, parent, offset))
    return Rig("horse", bones_from_rows(rows), {})


@pytest.mark.parametrize(
    ("rig", "note", "reins", "stirrups"),
    [
        (rows_without("leftRein", "rightRein"), "no rein bones", False, True),
        (
            rows_without("leftStirrupBar", "leftStirrup", "rightStirrupBar", "rightStirrup"),
            "no stirrup bones",
            True,
            False,
        ),
        (rows_without(longer={"leftStirrup": 10.0}), "absurd stirrup leathers", True, False),
        (rows_without(longer={"leftRein": 40.0}), "absurd rein", False, True),
    ],
)
def test_skeletons_without_tack_fall_back_to_appendix_b(rig: Rig, note: str, reins: bool, stirrups: bool) -> None:
    geometry = PartsGeometry.from_rigs(rig, rider_rig())
    assert geometry.has_reins is reins and geometry.has_stirrups is stirrups
    assert any(note in n for n in geometry.notes)
    parts = RiderParts(THESIS, geometry=geometry)
    frame = horse(horseNeck_rz=-25.0)
    rider = MODEL.evaluate(frame)
    rider[RIDER_INDEX["lf_foot.tx"]] += 0.1
    values = parts.evaluate(frame, rider)
    assert any(values[PART[f"lf_rein.{a}"]] for a in ("tx", "ty")) is reins
    assert any(values[PART[f"lf_stirrup.{a}"]] for a in ("tx", "ty")) is stirrups


def test_length_units_scale_out() -> None:
    """The same rider in centimetres gives the same parts in centimetres (slip is a fraction)."""
    frame = horse(horseNeck_rz=-70.0, horseHead_rz=60.0)
    rider = MODEL.evaluate(frame)
    rider[RIDER_INDEX["lf_foot.tx"]] += 0.1
    metres = PARTS.evaluate(frame, rider)
    in_cm = [v * 100.0 if c.kind is Kind.TRANSLATION else v for c, v in zip(RIDER, rider, strict=True)]
    centimetres = RiderParts(THESIS, metres_per_unit=0.01).evaluate(frame, in_cm)
    for name, m, cm in zip(RIDER_PART_NAMES, metres, centimetres):
        assert cm == pytest.approx(m if name == "reins.slip" else m * 100.0, rel=1e-9, abs=1e-12)


def test_batch_equals_the_live_path() -> None:
    take = generate_gait("canter", 2.0, 60.0)
    rng = np.random.default_rng(1)
    h = take.values.copy()
    h[:, HORSE_INDEX["horseNeck.rz"]] += rng.uniform(-60, 30, len(h))
    h[:, HORSE_INDEX["horseHead.rz"]] += rng.uniform(-40, 30, len(h))
    rider = MODEL.evaluate_batch(h)
    batch = PARTS.evaluate_batch(h, rider)
    live = np.array([PARTS.evaluate(list(a), list(b)) for a, b in zip(h, rider)])
    np.testing.assert_allclose(live, batch, rtol=0.0, atol=1e-12)
    assert batch[:, PART["reins.slip"]].any()  # both branches of the reach


def _bounded(name: str) -> st.SearchStrategy[float]:
    low, high = DEFAULT_RANGES.of(name)
    return st.floats(low, high, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(
    st.tuples(*(_bounded(n) for n in ("horseNeck.rz", "horseNeck.ry", "horseHead.rz"))),
    st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=len(RIDER_NAMES), max_size=len(RIDER_NAMES)),
)
def test_any_plausible_input_gives_finite_parts(neck: tuple[float, float, float], rider: list[float]) -> None:
    frame = horse(horseNeck_rz=neck[0], horseNeck_ry=neck[1], horseHead_rz=neck[2])
    values = PARTS.evaluate(frame, rider)
    assert all(math.isfinite(v) for v in values)
    assert 0.0 <= values[PART["reins.slip"]] < 1e6


@pytest.mark.skipif(not fastpath.AVAILABLE, reason="numba is not installed")
@settings(max_examples=150, deadline=None)
@given(
    st.tuples(*(_bounded(n) for n in ("horseNeck.rz", "horseNeck.ry", "horseHead.rz"))),
    st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=len(RIDER_NAMES), max_size=len(RIDER_NAMES)),
    st.fixed_dictionaries(
        {
            "reins.weight": st.floats(0.0, 1.0),
            "reins.length_scale": st.floats(0.5, 2.0),
            "reins.reach": st.floats(0.5, 1.0),
            "arms.in_gain": st.floats(-10.0, 10.0),
            "stirrups.weight": st.floats(0.0, 1.0),
            "stirrups.leather_scale": st.floats(0.5, 1.5),
        }
    ),
    st.sampled_from([1.0, 0.01, 4.0]),
)
def test_the_compiled_parts_are_the_python_source_exactly(
    neck: tuple[float, float, float], rider: list[float], knobs: dict[str, float], metres_per_unit: float
) -> None:
    """The live path runs the source compiled by numba: the same floats as the source on Python floats,
    for any preset values (they reach the compiled function as values, not as compiled-in constants)."""
    params = THESIS.with_values(knobs)
    frame = horse(horseNeck_rz=neck[0], horseNeck_ry=neck[1], horseHead_rz=neck[2])
    compiled = RiderParts(params, metres_per_unit, compiled=True).evaluate(frame, rider)
    python = RiderParts(params, metres_per_unit, compiled=False).evaluate(frame, rider)
    assert compiled == python
    assert all(type(v) is float for v in compiled)


@pytest.mark.skipif(not fastpath.AVAILABLE, reason="numba is not installed")
def test_a_parameter_change_reuses_the_compiled_function() -> None:
    """A live weight change must not compile (seconds in the tick): only the knobs change; nor may
    an input of another type (an int)."""
    changed = THESIS.with_values({"reins.weight": 0.5, "arms.in_gain": 1.5, "stirrups.leather_scale": 0.8})
    a, b = RiderParts(THESIS, compiled=True), RiderParts(changed, metres_per_unit=0.01, compiled=True)
    a.warm()
    b.warm()
    assert a._one is b._one  # type: ignore[attr-defined]
    assert len(a._one.signatures) == 1  # type: ignore[attr-defined]
    frame = horse(horseNeck_rz=-25, lfHoof_ty=0.2)  # an int, as a JSON or msgpack producer may send
    frame[HORSE_INDEX["horseHead.rz"]] = 10
    rider = MODEL.evaluate(frame)
    assert b.evaluate(frame, rider) == RiderParts(changed, 0.01, compiled=False).evaluate(frame, rider)
    assert len(a._one.signatures) == 1  # type: ignore[attr-defined]  # converted, never compiled in a loop


def test_parts_that_cannot_be_compiled_run_interpreted(monkeypatch: pytest.MonkeyPatch) -> None:
    """No writable cache directory for numba (a read-only install), or a compiler error: the tick
    must still start, with the same values from the same source, interpreted."""
    from riderlive.rules import parts as parts_module

    def cannot(*args: object) -> None:
        raise RuntimeError("cannot cache function 'parts': no locator available")

    monkeypatch.setattr(parts_module, "compiled_parts", cannot)
    unlucky = RiderParts(THESIS, compiled=True)
    unlucky.warm()
    frame = horse(horseNeck_rz=-40.0, horseHead_rz=20.0, lfHoof_ty=0.2)
    rider = MODEL.evaluate(frame)
    values = unlucky.evaluate(frame, rider)
    assert values == RiderParts(THESIS, compiled=False).evaluate(frame, rider)
    assert all(type(v) is float for v in values) and any(values)


def test_the_knobs_are_the_preset_and_the_skeletons() -> None:
    geo = default_geometry()
    assert geo.has_reins and geo.has_stirrups
    params = THESIS.with_values({"reins.length_scale": 1.5, "stirrups.leather_scale": 0.8})
    knobs = dict(zip(KNOBS, parts_knobs(params, geo, 0.04), strict=True))
    assert knobs["metres_per_unit"] == 0.04 and knobs["units_per_metre"] == pytest.approx(25.0, rel=1e-15)
    assert knobs["arm_gain"] == -THESIS.arms.in_gain and knobs["rein_weight"] == THESIS.reins.weight
    assert knobs["reach"] == pytest.approx(THESIS.reins.reach * geo.arm_length, rel=1e-15)
    assert knobs["foot_weight"] == THESIS.stirrups.weight
    assert knobs["left_leather"] == pytest.approx(0.8 * geo.leathers[0], rel=1e-15)
    for side, key in enumerate(("left_rein", "right_rein")):
        # the rest hand to its bit ring: neck joint + poll + ring (all at rest: no rotation), times 1.5
        ring = [geo.neck[i] + geo.poll[i] + geo.rings[side][i] for i in range(2)] + [geo.neck[2] + geo.rings[side][2]]
        rest = math.dist(geo.hands[side], ring)
        assert knobs[key] == pytest.approx(1.5 * rest, rel=1e-12)
        assert 0.2 < rest < 3.0


def test_part_parameters_are_validated() -> None:
    with pytest.raises(Exception, match="weight"):
        RuleParams().with_values({"reins.weight": 2.0})
    with pytest.raises(Exception, match="leather_scale"):
        RuleParams().with_values({"stirrups.leather_scale": 0.0})
    with pytest.raises(ValueError, match="metres_per_unit"):
        RiderParts(THESIS, metres_per_unit=0.0)
