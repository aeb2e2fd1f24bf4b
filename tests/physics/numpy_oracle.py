"""The previous implementation of the strand step, the bone chains and posing, in NumPy: the tests' oracle.

Until issue 18 this was the library's NumPy path, with hand-written numba twins beside
it. The library now has one source per algorithm (loops, compiled); this vectorised
formulation stays only here, so the compiled code is checked against an independent
reading of the same equations (tests/physics/test_oracle.py), never hand-mirrored in
the library. Same conventions as :mod:`riderlive.physics` (metres, degrees, (V, 3, N)).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.physics.attach import Frame, aim
from riderlive.physics.chain import FOLDED, ChainModel, ChainState
from riderlive.physics.collision import SKIN, WEDGE_SKIN, Capsules
from riderlive.physics.config import HorseBody, RiderBody
from riderlive.physics.quaternion import rotation_x, rotation_y, rotation_z
from riderlive.physics.strands import EXTRA_PASSES, MAX_WEDGE_SKIN, REPAIR_DEPTH, StrandModel, StrandState

FloatArray = npt.NDArray[np.float64]
_ONES3 = np.ones(3)


def _dot3(a: FloatArray, b: FloatArray) -> FloatArray:
    out: FloatArray = _ONES3 @ (a * b)
    return out


# ----------------------------------------------------------------------------- collisions


def _offsets(x: FloatArray, caps: Capsules) -> tuple[FloatArray, FloatArray, FloatArray]:
    a = caps.a[:, :, None, None]
    ab = (caps.b - caps.a)[:, :, None, None]
    axis = caps.b - caps.a
    inv_len2 = 1.0 / np.maximum((axis * axis) @ _ONES3, 1e-18)[:, None, None]
    p0 = x[None, :, 0] - a[:, 0]
    p1 = x[None, :, 1] - a[:, 1]
    p2 = x[None, :, 2] - a[:, 2]
    t = p0 * ab[:, 0]
    t += p1 * ab[:, 1]
    t += p2 * ab[:, 2]
    t *= inv_len2
    np.clip(t, 0.0, 1.0, out=t)
    p0 -= t * ab[:, 0]
    p1 -= t * ab[:, 1]
    p2 -= t * ab[:, 2]
    return p0, p1, p2


def push_out(x: FloatArray, caps: Capsules, skin: float = SKIN) -> float:
    d0, d1, d2 = _offsets(x, caps)
    dist2 = d0 * d0
    dist2 += d1 * d1
    dist2 += d2 * d2
    radius = caps.radius[:, None, None]
    inside = dist2 < radius * radius
    if not inside.any():
        return 0.0
    dist = np.sqrt(dist2)
    on_axis = inside & (dist < 1e-12)
    if on_axis.any():
        k, v, n = np.nonzero(on_axis)
        side = _perpendicular(caps.b[k] - caps.a[k])
        d0[k, v, n], d1[k, v, n], d2[k, v, n] = side[:, 0], side[:, 1], side[:, 2]
        dist[k, v, n] = 1.0
    scale = np.where(inside, (radius + skin) / np.maximum(dist, 1e-12) - 1.0, 0.0)
    deepest = float(np.max(np.where(inside, radius - dist, 0.0)))
    flat = scale.reshape(len(caps), -1)
    for c, d in enumerate((d0, d1, d2)):
        x[:, c] += (np.ones(len(caps)) @ (d.reshape(flat.shape) * flat)).reshape(x[:, c].shape)
    return deepest


def _perpendicular(axis: FloatArray) -> FloatArray:
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    out = np.cross(axis, helper)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    out = np.where(norm > 1e-12, out / np.maximum(norm, 1e-12), [[0.0, 0.0, 1.0]])
    return np.asarray(out, dtype=np.float64)


# ----------------------------------------------------------------------------- strands


def _pair_coefficients(wa: FloatArray, wb: FloatArray) -> tuple[FloatArray, FloatArray]:
    total = wa + wb
    safe = np.where(total > 0.0, total, 1.0)
    return (wa / safe)[:, None, :], (wb / safe)[:, None, :]


def _precompute(model: StrandModel) -> dict[str, FloatArray]:
    rest, w, bend = model.rest, np.asarray(model.inv_mass), np.asarray(model.bend)
    pre: dict[str, FloatArray] = {}
    for name, first in (("even", 0), ("odd", 1)):
        pre[f"{name}_rest"] = np.ascontiguousarray(rest[first::2])
        pre[f"{name}_ca"], pre[f"{name}_cb"] = _pair_coefficients(w[first:-1:2], w[first + 1 :: 2])
    wa, wb, wc = w[:-2], w[1:-1], w[2:]
    den = wb + 0.25 * (wa + wc)
    safe = np.where(den > 0.0, den, 1.0)
    k = bend[None, :] / safe
    pre["bend_b"] = (k * wb)[:, None, :]
    pre["bend_a"] = (0.5 * k * wa)[:, None, :]
    pre["bend_c"] = (0.5 * k * wc)[:, None, :]
    pre["keep"] = np.exp(-np.asarray(model.damping) * model.dt)
    return pre


def _distance_pass(x: FloatArray, pre: dict[str, FloatArray], name: str, first: int) -> None:
    a = x[first:-1:2]
    b = x[first + 1 :: 2]
    d = b - a
    length = np.sqrt(_dot3(d, d))
    np.maximum(length, 1e-12, out=length)
    f = pre[f"{name}_rest"] / length
    np.subtract(1.0, f, out=f)
    d *= f[:, None, :]
    a += pre[f"{name}_ca"] * d
    b -= pre[f"{name}_cb"] * d


def _bend_pass(x: FloatArray, pre: dict[str, FloatArray]) -> None:
    a, b, c = x[:-2], x[1:-1], x[2:]
    u = c - a
    m = b - a
    uu = _dot3(u, u)
    np.maximum(uu, 1e-18, out=uu)
    t = _dot3(m, u)
    t /= uu
    u *= t[:, None, :]
    m -= u
    b -= pre["bend_b"] * m
    a += pre["bend_a"] * m
    c += pre["bend_c"] * m


def _follow_the_leader(x: FloatArray, rest: FloatArray, pinned: int) -> FloatArray:
    before = x[pinned:].copy()
    for i in range(pinned, x.shape[0]):
        d = x[i] - x[i - 1]
        f = rest[i - 1] / np.sqrt(np.maximum(_ONES3 @ (d * d), 1e-24))
        f -= 1.0
        d *= f
        x[i] += d
    moves = np.zeros_like(x)
    np.subtract(x[pinned:], before, out=moves[pinned:])
    return moves


def strand_step(model: StrandModel, state: StrandState, pins: FloatArray, colliders: Capsules | None) -> StrandState:
    """The previous ``strands.step``."""
    pre = _precompute(model)
    x, prev = state.x, state.x_prev
    new = x - prev
    new *= pre["keep"]
    new += x
    new[:, 1, :] -= model.gravity * model.dt * model.dt
    new[: model.pinned] = pins
    if model.bends:
        _bend_pass(new, pre)
    caps = colliders if colliders is not None and len(colliders) > 0 else None
    free = new[model.pinned :]
    for _ in range(model.iterations):
        _distance_pass(new, pre, "even", 0)
        if model.n_vertices >= 3:
            _distance_pass(new, pre, "odd", 1)
        if caps is not None and model.collide_each_iteration:
            push_out(free, caps)
    moves = _follow_the_leader(new, model.rest, model.pinned)
    if caps is not None:
        for _ in range(model.collision_passes):
            if push_out(free, caps) < REPAIR_DEPTH:
                break
            _distance_pass(new, pre, "even", 0)
            if model.n_vertices >= 3:
                _distance_pass(new, pre, "odd", 1)
        wedge = WEDGE_SKIN
        for _ in range(EXTRA_PASSES):
            if push_out(free, caps, wedge) == 0.0:
                break
            wedge = min(2.0 * wedge, MAX_WEDGE_SKIN)
    prev_out = x.copy()
    prev_out[:-1] += model.leader_correction * moves[1:]
    return StrandState(new, prev_out)


# ----------------------------------------------------------------------------- chains


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def carry(a: FloatArray, b: FloatArray, v: FloatArray) -> FloatArray:
    scale = _dot3(v, b) / np.maximum(1.0 + _dot3(a, b), 1e-12)
    out: FloatArray = v - scale[:, None, :] * (a + b)
    return out


def _directions(x: FloatArray) -> FloatArray:
    d = x[1:] - x[:-1]
    d /= np.sqrt(np.maximum(_dot3(d, d), 1e-24))[:, None, :]
    return d


def _perpendicular_unit(up: FloatArray, axis: FloatArray) -> FloatArray:
    up = up - _dot3(up, axis)[:, None, :] * axis
    up /= np.sqrt(_dot3(up, up))[:, None, :]
    return up


def chain_rest_state(x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """The previous ``chain.rest_state``."""
    axis = _directions(x)
    up = np.empty_like(axis)
    up[0] = _perpendicular_unit(anchor_up[None], axis[:1])[0]
    for j in range(1, axis.shape[0]):
        up[j] = _perpendicular_unit(carry(axis[j - 1 : j], axis[j : j + 1], up[j - 1 : j]), axis[j : j + 1])[0]
    zeros = np.zeros(axis[:, 0].shape)
    return ChainState(axis, up, zeros, zeros.copy())


def chain_step(model: ChainModel, state: ChainState, x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """The previous ``chain.step``."""
    axis = _directions(x)
    carried = carry(state.axis, axis, state.up)
    up = carried.copy()
    up[0] = anchor_up
    up = _perpendicular_unit(up, axis)
    side = _cross(axis, up)
    turned = np.zeros(axis[:, 0].shape)
    turned[0] = np.arctan2(-_dot3(carried[:1], side[:1]), _dot3(carried[:1], up[:1]))[0]
    if axis.shape[0] > 1:
        ref = carry(axis[:-1], axis[1:], up[:-1])
        share = np.arctan2(-_dot3(ref, side[1:]), _dot3(ref, up[1:]))
        share *= model.twist_share
        share[_dot3(axis[:-1], axis[1:]) < FOLDED] = 0.0
        turn = np.zeros(turned.shape)
        turn[1:] -= 0.5 * share
        turn[1] -= 0.5 * share[0]
        turn[1:-1] += 0.5 * share[1:]
        up = up * np.cos(turn)[:, None, :] + side * np.sin(turn)[:, None, :]
        turned += turn
    velocity = turned / model.dt
    target = np.minimum(model.fan_gain * np.abs(velocity) * model.fan_profile, model.fan_max)
    fan = state.fan + model.fan_share * (target - state.fan)
    return ChainState(axis, up, velocity, fan)


# ----------------------------------------------------------------------------- posing


def _h(frame: FloatArray, name: str) -> float:
    return float(frame[HORSE_INDEX[name]])


def _r(rider: FloatArray | None, name: str) -> float:
    return 0.0 if rider is None else float(rider[RIDER_INDEX[name]])


_ROOT = [HORSE_INDEX[f"root.{a}"] for a in ("tx", "ty", "tz")]
_PIVOT = [HORSE_INDEX[f"rearPivot.{a}"] for a in ("tx", "ty", "tz")]
_HOOVES = [[HORSE_INDEX[f"{h}.{a}"] for a in ("tx", "ty", "tz")] for h in ("lbHoof", "rbHoof")]


class Posing:
    """The previous ``attach.HorseAttachment`` and ``RiderAttachment``: frames and colliders by NumPy."""

    def __init__(self, horse: HorseBody, rider: RiderBody) -> None:
        self.pivot_rest = np.array(horse.pivot_rest)
        self.dock_offset = np.array(horse.dock_offset)
        self.dock_rest = aim(horse.dock_direction)
        self.centre = np.array(horse.hindquarters_centre)
        self.hips = np.array([horse.hip_offset, horse.hip_offset]) * np.array([[1.0, 1.0, -1.0], [1.0, 1.0, 1.0]])
        rest = np.array(horse.hind_hoof_rest) + np.array([0.0, horse.leg_radius, 0.0])
        self.hoof_shift = np.array([rest * np.array([1.0, 1.0, -1.0]), rest])
        self.radius = np.array([horse.hindquarters_radius, horse.leg_radius, horse.leg_radius])
        self.lift_limit = rider.lift_limit
        self.seat = np.array(rider.seat_offset)
        self.head_offset = np.array([0.0, rider.head_height, 0.0])
        self.back_ends = np.array([rider.back_bottom, rider.back_top])
        self.back_radius = np.array([rider.back_radius])
        self.braid_offset = np.array(rider.braid_offset)
        self.braid_rest = aim(rider.braid_direction)
        self.hair_gains = (rider.hair_up_gain, rider.hair_side_gain)
        mirror = np.diag([1.0, 1.0, -1.0])
        self.cloth_offsets = np.array([np.array(rider.cloth_offset) * np.diag(mirror), rider.cloth_offset])
        self.cloth_rest = (mirror @ aim(rider.cloth_direction) @ mirror, aim(rider.cloth_direction))
        self.cloth_gains = (rider.cloth_up_gain, rider.cloth_side_gain, rider.cloth_tilt_limit)

    def hindquarters(self, frame: FloatArray) -> Frame:
        yaw = rotation_y(_h(frame, "root.ry"))
        rot = (
            rotation_y(_h(frame, "root.ry") + _h(frame, "rearPivot.ry"))
            @ rotation_z(_h(frame, "rearPivot.rz"))
            @ rotation_x(_h(frame, "rearPivot.rx"))
        )
        return Frame(frame[_ROOT] + yaw @ (frame[_PIVOT] + self.pivot_rest), rot)

    def dock(self, hq: Frame) -> Frame:
        return Frame(hq.origin + hq.rotation @ self.dock_offset, hq.rotation @ self.dock_rest)

    def colliders(self, frame: FloatArray, hq: Frame) -> Capsules:
        centre = hq.origin + hq.rotation @ self.centre
        hips = hq.origin + self.hips @ hq.rotation.T
        hooves = frame[_ROOT] + (frame[_HOOVES] + self.hoof_shift) @ rotation_y(_h(frame, "root.ry")).T
        return Capsules(np.vstack((centre, hips)), np.vstack((centre, hooves)), self.radius)

    def rider(self, hq: Frame, rider: FloatArray | None) -> tuple[Frame, Frame, Capsules, Frame, list[Frame]]:
        """Head frame, braid frame, the back capsule, the hips frame and the flaps' frames (left, right)."""
        lift = min(max(_r(rider, "cog.ty"), -self.lift_limit), self.lift_limit)
        seat = hq.origin + hq.rotation @ (self.seat + np.array([0.0, lift, 0.0]))
        spine = (
            hq.rotation
            @ rotation_x(_r(rider, "lower_back.rx"))
            @ rotation_y(_r(rider, "lower_back.ry"))
            @ rotation_z(-_r(rider, "lower_back.rz"))
        )
        head_rot = spine @ rotation_y(_r(rider, "head.ry")) @ rotation_z(-_r(rider, "head.rz"))
        back = seat + self.back_ends @ spine.T
        head = Frame(seat + spine @ self.head_offset, head_rot)
        up, side = self.hair_gains  # section 8.9: the attributes tilt the braid's tie
        tilt = rotation_z(-up * _r(rider, "hair.up")) @ rotation_x(-side * _r(rider, "hair.side"))
        braid = Frame(head.point(self.braid_offset), head.rotation @ tilt @ self.braid_rest)
        hips = Frame(seat, spine)
        up, side, limit = self.cloth_gains  # and the cloth attributes both flaps' ties, each tilt limited
        rise = float(np.clip(up * _r(rider, "cloth.up"), -limit, limit))
        swing = float(np.clip(side * _r(rider, "cloth.side"), -limit, limit))
        skirt = spine @ rotation_z(-rise) @ rotation_x(-swing)
        flaps = [Frame(hips.point(o), skirt @ r) for o, r in zip(self.cloth_offsets, self.cloth_rest, strict=True)]
        return head, braid, Capsules(back[:1], back[1:], self.back_radius), hips, flaps

    def anchors(
        self, horse: FloatArray, rider: FloatArray | None, *roots: float
    ) -> tuple[FloatArray, FloatArray, Capsules, Frame, Frame, Frame]:
        """The previous ``SkinnedModel.anchors`` with the flaps: pins (2, 3, 4), up (3, 4), colliders,
        hindquarters, head, hips; ``roots`` are the tail's, braid's and (both) flaps' pinned lengths."""
        hq = self.hindquarters(horse)
        tail = self.dock(hq)
        head, braid, back, hips, flaps = self.rider(hq, rider)
        frames = [tail, braid, *flaps]
        base = np.stack([f.origin for f in frames], axis=1)
        along = np.stack([f.rotation[:, 0] * r for f, r in zip(frames, roots, strict=True)], axis=1)
        up = np.stack([f.rotation[:, 1] for f in frames], axis=1)
        colliders = Capsules.concat(self.colliders(horse, hq), back)
        return np.stack((base, base + along)), up, colliders, hq, head, hips
