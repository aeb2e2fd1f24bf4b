"""Compiled (numba) twins of the small-model physics: posing, the strand step and the bone chains.

The skinned tail and the braid are two strands of 12 vertices: for arrays that small
every NumPy call costs its fixed ~1 us whatever the size, and one step makes about
300 of them. These kernels do the same arithmetic, in the same order, as
:func:`riderlive.physics.strands.step`, :func:`riderlive.physics.chain.step` and
:meth:`riderlive.physics.skinned.SkinnedModel.anchors` on plain float64 arrays, in
loops, so a step costs a few microseconds (results agree with the NumPy path within
1e-12 per step, tested; in practice to the last few bits). The NumPy code stays the reference and serves the
many-strand tail, which it already runs within its budget.

Selection: :data:`AVAILABLE` is True when numba imports; ``SkinnedModel.build(config,
compiled=False)`` (or ``riderlive tail --numpy``) keeps the NumPy path. Compiled
code is cached on disk (``cache=True``, in ``__pycache__``): the first call in a
fresh checkout compiles (about 9 s of CPU), later processes load it (0.3 s). The wrappers pass
contiguous float64 arrays and plain scalars only, so each kernel compiles once.
Constants come in as arguments, never as globals of other modules (numba's cache
would not see them change).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from importlib.util import find_spec
from typing import Any, TypeVar, cast

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.physics.attach import Frame, HorseAttachment, RiderAttachment
from riderlive.physics.chain import FOLDED, ChainModel, ChainState
from riderlive.physics.collision import SKIN, WEDGE_SKIN, Capsules
from riderlive.physics.drive import Drive
from riderlive.physics.strands import EXTRA_PASSES, MAX_WEDGE_SKIN, REPAIR_DEPTH, StrandModel, StrandState

FloatArray = npt.NDArray[np.float64]
F = TypeVar("F", bound=Callable[..., Any])

AVAILABLE = find_spec("numba") is not None
"""numba is installed (a dependency; without it the NumPy path still works)."""


def _jit(fn: F) -> F:
    """``numba.njit`` with a disk cache, NumPy's division semantics and the GIL released; identity without numba."""
    if not AVAILABLE:  # pragma: no cover
        return fn
    import numba

    return cast(F, numba.njit(cache=True, error_model="numpy", nogil=True)(fn))


# ----------------------------------------------------------------------------- strands


@_jit
def _fmax(a: float, b: float) -> float:
    """np.maximum for scalars (NaN propagates)."""
    return a if (a >= b or math.isnan(a)) else b


Vec = tuple[float, float, float]
"""A 3-vector as a tuple: numba keeps it in registers (array expressions compile slowly and allocate)."""


@_jit
def _at(a: FloatArray, i: int, s: int) -> Vec:
    """Row ``i``, column ``s`` of a (rows, 3, columns) array."""
    return (a[i, 0, s], a[i, 1, s], a[i, 2, s])


@_jit
def _put(a: FloatArray, i: int, s: int, v: Vec) -> None:
    a[i, 0, s], a[i, 1, s], a[i, 2, s] = v


@_jit
def _sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@_jit
def _dot(a: Vec, b: Vec) -> float:
    """Summed in index order, as NumPy's matmul with a ones vector does."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@_jit
def _distance_pass(x: FloatArray, rest: FloatArray, w: FloatArray, first: int) -> None:
    n_vert, _, n = x.shape
    for i in range(first, n_vert - 1, 2):
        for s in range(n):
            wa, wb = w[i, s], w[i + 1, s]
            total = wa + wb
            safe = total if total > 0.0 else 1.0
            d0 = x[i + 1, 0, s] - x[i, 0, s]
            d1 = x[i + 1, 1, s] - x[i, 1, s]
            d2 = x[i + 1, 2, s] - x[i, 2, s]
            f = 1.0 - rest[i, s] / _fmax(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2), 1e-12)
            d0, d1, d2 = d0 * f, d1 * f, d2 * f
            ca, cb = wa / safe, wb / safe
            x[i, 0, s] += ca * d0
            x[i, 1, s] += ca * d1
            x[i, 2, s] += ca * d2
            x[i + 1, 0, s] -= cb * d0
            x[i + 1, 1, s] -= cb * d1
            x[i + 1, 2, s] -= cb * d2


@_jit
def _bend_pass(x: FloatArray, w: FloatArray, bend: FloatArray) -> None:
    n_vert, _, n = x.shape
    m = np.empty((n_vert - 2, 3, n))
    k = np.empty((n_vert - 2, 3, n))  # coefficients for a, b, c (in the coordinate slot)
    for i in range(n_vert - 2):
        for s in range(n):
            u = _sub(_at(x, i + 2, s), _at(x, i, s))
            mm = _sub(_at(x, i + 1, s), _at(x, i, s))
            t = _dot(mm, u) / _fmax(_dot(u, u), 1e-18)
            _put(m, i, s, (mm[0] - u[0] * t, mm[1] - u[1] * t, mm[2] - u[2] * t))
            wa, wb, wc = w[i, s], w[i + 1, s], w[i + 2, s]
            den = wb + 0.25 * (wa + wc)
            kk = bend[s] / (den if den > 0.0 else 1.0)
            k[i, 0, s], k[i, 1, s], k[i, 2, s] = 0.5 * kk * wa, kk * wb, 0.5 * kk * wc
    for i in range(n_vert - 2):  # the same order of updates as the NumPy pass: b, then a, then c
        for c in range(3):
            for s in range(n):
                x[i + 1, c, s] -= k[i, 1, s] * m[i, c, s]
    for i in range(n_vert - 2):
        for c in range(3):
            for s in range(n):
                x[i, c, s] += k[i, 0, s] * m[i, c, s]
    for i in range(n_vert - 2):
        for c in range(3):
            for s in range(n):
                x[i + 2, c, s] += k[i, 2, s] * m[i, c, s]


@_jit
def _follow_the_leader(x: FloatArray, rest: FloatArray, pinned: int) -> FloatArray:
    n_vert, _, n = x.shape
    moves = np.zeros_like(x)
    for i in range(pinned, n_vert):
        for s in range(n):
            d0 = x[i, 0, s] - x[i - 1, 0, s]
            d1 = x[i, 1, s] - x[i - 1, 1, s]
            d2 = x[i, 2, s] - x[i - 1, 2, s]
            f = rest[i - 1, s] / math.sqrt(_fmax(d0 * d0 + d1 * d1 + d2 * d2, 1e-24)) - 1.0
            d = (d0, d1, d2)
            for c in range(3):
                before = x[i, c, s]
                x[i, c, s] += d[c] * f
                moves[i, c, s] = x[i, c, s] - before
    return moves


@_jit
def _push_out(  # noqa: PLR0917
    x: FloatArray, first: int, a: FloatArray, b: FloatArray, radius: FloatArray, skin: float
) -> float:
    """collision.push_out on vertices ``first:`` of ``x``: every capsule's push from the same positions."""
    n_vert, _, n = x.shape
    k_caps = radius.shape[0]
    ab = np.empty((k_caps, 3))
    inv_len2 = np.empty(k_caps)
    for k in range(k_caps):
        for c in range(3):
            ab[k, c] = b[k, c] - a[k, c]
        inv_len2[k] = 1.0 / _fmax(ab[k, 0] * ab[k, 0] + ab[k, 1] * ab[k, 1] + ab[k, 2] * ab[k, 2], 1e-18)
    off = np.empty((k_caps, 3))
    scale = np.empty(k_caps)
    deepest = -np.inf
    inside_any, outside_any = False, False
    for v in range(first, n_vert):
        for s in range(n):
            pushed = False
            for k in range(k_caps):
                p0, p1, p2 = x[v, 0, s] - a[k, 0], x[v, 1, s] - a[k, 1], x[v, 2, s] - a[k, 2]
                t = (p0 * ab[k, 0] + p1 * ab[k, 1] + p2 * ab[k, 2]) * inv_len2[k]
                t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                p0, p1, p2 = p0 - t * ab[k, 0], p1 - t * ab[k, 1], p2 - t * ab[k, 2]
                dist2 = p0 * p0 + p1 * p1 + p2 * p2
                r = radius[k]
                scale[k] = 0.0
                off[k, 0], off[k, 1], off[k, 2] = p0, p1, p2
                if not dist2 < r * r:
                    outside_any = True
                    continue
                inside_any, pushed = True, True
                dist = math.sqrt(dist2)
                if dist < 1e-12:  # on the axis: leave sideways, as collision.push_out does
                    off[k, 0], off[k, 1], off[k, 2] = _perpendicular((ab[k, 0], ab[k, 1], ab[k, 2]))
                    dist = 1.0
                scale[k] = (r + skin) / _fmax(dist, 1e-12) - 1.0
                deepest = max(deepest, r - dist)
            if pushed:
                for c in range(3):
                    acc = 0.0
                    for k in range(k_caps):
                        acc += off[k, c] * scale[k]
                    x[v, c, s] += acc
    if not inside_any:
        return 0.0
    return max(deepest, 0.0) if outside_any else deepest


@_jit
def _perpendicular(axis: Vec) -> Vec:
    """collision._perpendicular for one axis."""
    h0, h1 = (1.0, 0.0) if abs(axis[0]) < 0.9 else (0.0, 1.0)
    out = (-axis[2] * h1, axis[2] * h0, axis[0] * h1 - axis[1] * h0)
    norm = math.sqrt(_dot(out, out))
    if norm > 1e-12:
        return (out[0] / norm, out[1] / norm, out[2] / norm)
    return (0.0, 0.0, 1.0)


@_jit
def _strand_step(  # noqa: PLR0917
    x: FloatArray,
    prev: FloatArray,
    pins: FloatArray,
    rest: FloatArray,
    w: FloatArray,
    bend: FloatArray,
    keep: FloatArray,
    cap_a: FloatArray,
    cap_b: FloatArray,
    cap_r: FloatArray,
    pinned: int,
    iterations: int,
    collision_passes: int,
    extra_passes: int,
    bends: bool,
    collide_each: bool,
    fall: float,
    leader: float,
    repair_depth: float,
    skin: float,
    wedge_skin: float,
) -> tuple[FloatArray, FloatArray]:
    """strands.step; ``fall`` is gravity * dt * dt."""
    n_vert, _, n = x.shape
    new = np.empty_like(x)
    for i in range(n_vert):
        for c in range(3):
            for s in range(n):
                new[i, c, s] = (x[i, c, s] - prev[i, c, s]) * keep[s] + x[i, c, s]
        for s in range(n):
            new[i, 1, s] -= fall
    for i in range(pinned):
        for c in range(3):
            for s in range(n):
                new[i, c, s] = pins[i, c, s]
    if bends:
        _bend_pass(new, w, bend)
    caps = cap_r.shape[0] > 0
    for _ in range(iterations):
        _distance_pass(new, rest, w, 0)
        _distance_pass(new, rest, w, 1)
        if caps and collide_each:
            _push_out(new, pinned, cap_a, cap_b, cap_r, skin)
    moves = _follow_the_leader(new, rest, pinned)
    if caps:
        for _ in range(collision_passes):
            if _push_out(new, pinned, cap_a, cap_b, cap_r, skin) < repair_depth:
                break
            _distance_pass(new, rest, w, 0)
            _distance_pass(new, rest, w, 1)
        wedge = wedge_skin
        for _ in range(extra_passes):
            if _push_out(new, pinned, cap_a, cap_b, cap_r, wedge) == 0.0:
                break
            wedge = min(2.0 * wedge, MAX_WEDGE_SKIN)
    out_prev = x.copy()
    for i in range(n_vert - 1):
        for c in range(3):
            for s in range(n):
                out_prev[i, c, s] += leader * moves[i + 1, c, s]
    return new, out_prev


def _c(a: FloatArray) -> FloatArray:
    return np.ascontiguousarray(a, dtype=np.float64)


_NO_CAPS = Capsules.empty()


def strand_step(
    model: StrandModel, state: StrandState, pins: FloatArray, colliders: Capsules | None = None
) -> StrandState:
    """:func:`riderlive.physics.strands.step`, compiled (same contract, same results within 1e-12)."""
    caps = _NO_CAPS if colliders is None else colliders
    new, prev = _strand_step(
        _c(state.x),
        _c(state.x_prev),
        _c(pins),
        model.rest,
        cast(FloatArray, model.inv_mass),
        cast(FloatArray, model.bend),
        model._pre["keep"],
        _c(caps.a),
        _c(caps.b),
        _c(caps.radius),
        int(model.pinned),
        int(model.iterations),
        int(model.collision_passes),
        EXTRA_PASSES,
        model._bends,
        bool(model.collide_each_iteration),
        float(model.gravity * model.dt * model.dt),
        float(model.leader_correction),
        REPAIR_DEPTH,
        SKIN,
        WEDGE_SKIN,
    )
    return StrandState(new, prev)


# ----------------------------------------------------------------------------- bone chains


@_jit
def _carry(a: Vec, b: Vec, v: Vec) -> Vec:
    """chain.carry for one vector."""
    scale = _dot(v, b) / _fmax(1.0 + _dot(a, b), 1e-12)
    return (v[0] - scale * (a[0] + b[0]), v[1] - scale * (a[1] + b[1]), v[2] - scale * (a[2] + b[2]))


@_jit
def _chain_step(  # noqa: PLR0917
    old_axis: FloatArray,
    old_up: FloatArray,
    old_fan: FloatArray,
    x: FloatArray,
    anchor_up: FloatArray,
    fan_profile: FloatArray,
    dt: float,
    twist_share: float,
    fan_share: float,
    fan_gain: float,
    fan_max: float,
    folded: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """chain.step, one chain (column) at a time."""
    n_bones, _, n = old_axis.shape
    axis = np.empty_like(old_axis)
    up = np.empty_like(old_up)
    side = np.empty_like(old_up)
    velocity = np.empty_like(old_fan)
    fan = np.empty_like(old_fan)
    turn = np.zeros(n_bones)
    share = np.zeros(n_bones)
    for ch in range(n):
        carried0 = (0.0, 0.0, 0.0)
        for j in range(n_bones):
            d = _sub(_at(x, j + 1, ch), _at(x, j, ch))
            norm = math.sqrt(_fmax(_dot(d, d), 1e-24))
            a = (d[0] / norm, d[1] / norm, d[2] / norm)
            carried = _carry(_at(old_axis, j, ch), a, _at(old_up, j, ch))
            if j == 0:
                carried0 = carried
                carried = (anchor_up[0, ch], anchor_up[1, ch], anchor_up[2, ch])
            k = _dot(carried, a)
            u = (carried[0] - k * a[0], carried[1] - k * a[1], carried[2] - k * a[2])
            norm = math.sqrt(_dot(u, u))
            u = (u[0] / norm, u[1] / norm, u[2] / norm)
            _put(axis, j, ch, a)
            _put(up, j, ch, u)
            _put(side, j, ch, (a[1] * u[2] - a[2] * u[1], a[2] * u[0] - a[0] * u[2], a[0] * u[1] - a[1] * u[0]))
        turned0 = math.atan2(-_dot(carried0, _at(side, 0, ch)), _dot(carried0, _at(up, 0, ch)))
        for j in range(n_bones):
            turn[j] = 0.0
        if n_bones > 1:
            for j in range(n_bones - 1):
                ref = _carry(_at(axis, j, ch), _at(axis, j + 1, ch), _at(up, j, ch))
                share[j] = math.atan2(-_dot(ref, _at(side, j + 1, ch)), _dot(ref, _at(up, j + 1, ch))) * twist_share
                if _dot(_at(axis, j, ch), _at(axis, j + 1, ch)) < folded:
                    share[j] = 0.0
            for j in range(1, n_bones):
                turn[j] -= 0.5 * share[j - 1]
            turn[1] -= 0.5 * share[0]
            for j in range(1, n_bones - 1):
                turn[j] += 0.5 * share[j]
            for j in range(n_bones):
                cs, sn = math.cos(turn[j]), math.sin(turn[j])
                for c in range(3):
                    up[j, c, ch] = up[j, c, ch] * cs + side[j, c, ch] * sn
        for j in range(n_bones):
            velocity[j, ch] = ((turned0 if j == 0 else 0.0) + turn[j]) / dt
            target = min(fan_gain * abs(velocity[j, ch]) * fan_profile[j, ch], fan_max)
            fan[j, ch] = old_fan[j, ch] + fan_share * (target - old_fan[j, ch])
    return axis, up, velocity, fan


def chain_step(model: ChainModel, state: ChainState, x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """:func:`riderlive.physics.chain.step`, compiled (same contract, same results within 1e-12)."""
    axis, up, velocity, fan = _chain_step(
        _c(state.axis),
        _c(state.up),
        _c(state.fan),
        _c(x),
        _c(anchor_up),
        _c(model.fan_profile),
        float(model.dt),
        model.twist_share,
        model.fan_share,
        float(model.fan_gain),
        float(model.fan_max),
        FOLDED,
    )
    return ChainState(axis, up, velocity, fan)


# ----------------------------------------------------------------------------- posing

HORSE_POSE = np.array(
    [HORSE_INDEX[f"root.{a}"] for a in ("tx", "ty", "tz", "ry")]
    + [HORSE_INDEX[f"rearPivot.{a}"] for a in ("tx", "ty", "tz", "ry", "rz", "rx")]
    + [HORSE_INDEX[f"{h}.{a}"] for h in ("lbHoof", "rbHoof") for a in ("tx", "ty", "tz")]
)
"""Horse channels the posing kernel reads, in its order."""
RIDER_POSE = np.array(
    [RIDER_INDEX[n] for n in ("cog.ty", "lower_back.rx", "lower_back.ry", "lower_back.rz", "head.ry", "head.rz")]
)
"""Rider channels the posing kernel reads, in its order (zeros without a rider: upright)."""
_UPRIGHT = np.zeros(len(RIDER_POSE))
# Rows of the posing kernel's ``points`` table (metres, in the frame attach.py names).
PIVOT, DOCK, CENTRE, HIP_L, HIP_R, HOOF_L, HOOF_R, SEAT, HEAD, BACK_LO, BACK_HI, BRAID = range(12)


@_jit
def _rot(axis: int, deg: float) -> FloatArray:
    """quaternion.rotation_x/y/z: 3x3 rotation about axis 0, 1 or 2 by ``deg`` degrees."""
    rad = deg * (math.pi / 180.0)
    c, s = math.cos(rad), math.sin(rad)
    m = np.zeros((3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m[axis, axis] = 1.0
    m[i, i], m[j, j] = c, c
    m[i, j], m[j, i] = -s, s
    return m


@_jit
def _mat(a: FloatArray, b: FloatArray) -> FloatArray:
    """a @ b for 3x3 matrices, summed in index order (numba's @ would need SciPy's BLAS)."""
    out = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            out[r, c] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]
    return out


@_jit
def _place(origin: FloatArray, m: FloatArray, v: FloatArray, shift: FloatArray, out: FloatArray) -> None:
    """out = origin + m @ (v + shift), for 3x3 ``m`` and 3-vectors."""
    p = (v[0] + shift[0], v[1] + shift[1], v[2] + shift[2])
    for r in range(3):
        out[r] = origin[r] + (m[r, 0] * p[0] + m[r, 1] * p[1] + m[r, 2] * p[2])


@_jit
def _pose(  # noqa: PLR0917
    h: FloatArray,
    rider: FloatArray,
    points: FloatArray,
    dock_rest: FloatArray,
    braid_rest: FloatArray,
    lift_limit: float,
    tail_root: float,
    braid_root: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """SkinnedModel.anchors: pins (2, 3, 2), up (3, 2), capsule ends (4, 3) x 2, hindquarters and head frames."""
    zero = np.zeros(3)
    root = h[0:3]
    yaw = _rot(1, h[3])
    hq_rot = _mat(_mat(_rot(1, h[3] + h[7]), _rot(2, h[8])), _rot(0, h[9]))
    hq, dock, seat, head, braid = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    _place(root, yaw, h[4:7], points[PIVOT], hq)
    _place(hq, hq_rot, points[DOCK], zero, dock)
    dock_rot = _mat(hq_rot, dock_rest)
    cap_a, cap_b = np.empty((4, 3)), np.empty((4, 3))
    _place(hq, hq_rot, points[CENTRE], zero, cap_a[0])
    _place(hq, hq_rot, points[CENTRE], zero, cap_b[0])
    _place(hq, hq_rot, points[HIP_L], zero, cap_a[1])
    _place(hq, hq_rot, points[HIP_R], zero, cap_a[2])
    _place(root, yaw, h[10:13], points[HOOF_L], cap_b[1])
    _place(root, yaw, h[13:16], points[HOOF_R], cap_b[2])
    lift = np.zeros(3)
    lift[1] = min(max(rider[0], -lift_limit), lift_limit)
    _place(hq, hq_rot, points[SEAT], lift, seat)
    spine = _mat(_mat(_mat(hq_rot, _rot(0, rider[1])), _rot(1, rider[2])), _rot(2, -rider[3]))
    head_rot = _mat(_mat(spine, _rot(1, rider[4])), _rot(2, -rider[5]))
    _place(seat, spine, points[BACK_LO], zero, cap_a[3])
    _place(seat, spine, points[BACK_HI], zero, cap_b[3])
    _place(seat, spine, points[HEAD], zero, head)
    _place(head, head_rot, points[BRAID], zero, braid)
    braid_rot = _mat(head_rot, braid_rest)
    pins, up = np.empty((2, 3, 2)), np.empty((3, 2))
    for c in range(3):
        pins[0, c, 0], pins[0, c, 1] = dock[c], braid[c]
        pins[1, c, 0] = dock[c] + dock_rot[c, 0] * tail_root
        pins[1, c, 1] = braid[c] + braid_rot[c, 0] * braid_root
        up[c, 0], up[c, 1] = dock_rot[c, 1], braid_rot[c, 1]
    return pins, up, cap_a, cap_b, hq, hq_rot, head, head_rot


class CompiledPose:
    """The anchors of the tail and braid (SkinnedModel.anchors), compiled; constants gathered once."""

    def __init__(self, horse: HorseAttachment, rider: RiderAttachment, tail_root: float, braid_root: float) -> None:
        self.points = _c(
            np.vstack(
                (
                    horse.pivot_rest,
                    horse.dock_offset,
                    horse.centre,
                    horse.hips,
                    horse.hoof_shift,
                    rider.seat,
                    rider.head_offset,
                    rider.back_ends,
                    rider.braid_offset,
                )
            )
        )
        self.dock_rest, self.braid_rest = _c(horse.dock_rest), _c(rider.braid_rest)
        self.radius = _c(np.concatenate((horse.radius, rider.back_radius)))
        self.scalars = (float(rider.lift_limit), float(tail_root), float(braid_root))

    def __call__(self, drive: Drive) -> tuple[FloatArray, FloatArray, Capsules, Frame, Frame]:
        """Pins (2, 3, 2), bone 0 up vectors (3, 2), colliders, hindquarters and head frames for ``drive``."""
        rider = _UPRIGHT if drive.rider is None else _c(drive.rider[RIDER_POSE])
        pins, up, a, b, hq, hq_rot, head, head_rot = _pose(
            _c(drive.horse[HORSE_POSE]), rider, self.points, self.dock_rest, self.braid_rest, *self.scalars
        )
        return pins, up, Capsules(a, b, self.radius), Frame(hq, hq_rot), Frame(head, head_rot)
