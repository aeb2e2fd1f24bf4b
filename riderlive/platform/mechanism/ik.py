"""Inverse kinematics, written once for Python floats (the tick) and NumPy arrays (a bake).

:func:`make_ik` binds a :class:`~riderlive.platform.mechanism.geometry.Geometry` into a function
of a pose ``(tx, ty, tz, rx, ry, rz)`` of the cue centre (m, deg, base frame; see
:mod:`riderlive.platform.mechanism.geometry`) that returns every actuator's position and how far
the pose is from the rotary arms' reach. Only the primitives in :class:`Ops` differ
between the scalar and the array form, as in :mod:`riderlive.rules.kuhnel2003`.

Per actuator ``i`` the leg vector is ``l = t + R p_i - b_i`` (``t`` the cue centre,
``p_i`` the platform joint from the cue centre, ``b_i`` the base joint):

- linear: position ``|l| - min_length`` (m);
- rotary: the arm angle ``alpha`` that puts the arm's tip one rod length from the
  platform joint. With the arm along ``d_i cos(alpha) + up sin(alpha)``,
  ``|l - a (d cos + up sin)|^2 = s^2`` gives ``M sin(alpha) + N cos(alpha) = L`` with
  ``L = |l|^2 - (s^2 - a^2)``, ``M = 2 a l_y``, ``N = 2 a (d . l)``, so
  ``alpha = asin(L / hypot(M, N)) - atan2(N, M)`` (the branch with the arm near
  horizontal). ``|L| > hypot(M, N)`` means the rod cannot reach: the pose is out of reach.

The heave-pitch-roll rig ignores ``tx``, ``tz`` and ``ry`` (its guide holds them at 0).

:func:`make_workspace` adds the workspace check and the scale-back: a pose outside the
soft limits is moved back toward home along the straight line from home to it, to
the last point inside (Illinois regula falsi, a fixed number of steps, the same on
floats and arrays). :func:`forward` solves the forward kinematics numerically
(Newton), for checks; :func:`axis_ranges` finds how far each pose axis reaches alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive.platform.mechanism.geometry import Geometry, Pose

FloatArray = npt.NDArray[np.float64]
DEG = math.pi / 180.0
SHRINK_STEPS = 8
"""Regula falsi steps of the scale-back: the kept pose ends within 2 % of an actuator's range of its limit."""
SHRINK_SCAN = 8
"""Points the line from home to a pose outside is sampled at (1/8 apart) before the regula
falsi, which then searches the first eighth that leaves the workspace: the line may leave and
enter again (``stewart_linear`` at y 0.56 m, yaw 51 deg: out at 0.25, in again at 0.65), and a
search over [0, 1] found either crossing (scale 0.70 or 0.13 for two neighbouring poses)."""


def _where_scalar(cond: Any, a: Any, b: Any) -> Any:
    return a if cond else b


@dataclass(frozen=True, slots=True)
class Ops:
    """The primitives whose scalar and array forms differ."""

    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    sqrt: Callable[[Any], Any]
    asin: Callable[[Any], Any]
    atan2: Callable[[Any, Any], Any]
    abs: Callable[[Any], Any]
    minimum: Callable[[Any, Any], Any]
    maximum: Callable[[Any, Any], Any]
    where: Callable[[Any, Any, Any], Any]


SCALAR = Ops(math.sin, math.cos, math.sqrt, math.asin, math.atan2, abs, min, max, _where_scalar)
"""Python floats. The builtin ``min``/``max`` equal NumPy's for finite values, which is all the
cueing ever hands the IK (it holds non-finite saddle values)."""
ARRAY = Ops(np.sin, np.cos, np.sqrt, np.arcsin, np.arctan2, np.abs, np.minimum, np.maximum, np.where)

IkFunction = Callable[..., tuple[tuple[Any, ...], Any]]
"""``ik(tx, ty, tz, rx, ry, rz) -> (positions, reach)``; ``reach < 0``: a rod cannot reach."""


def make_ik(g: Geometry, ops: Ops) -> IkFunction:
    """Return ``ik(tx, ty, tz, rx, ry, rz) -> (positions, reach)`` for ``g`` on ``ops``.

    ``positions`` has one entry per actuator (m or deg). ``reach`` is ``1 - max |L| /
    hypot(M, N)`` over the rotary actuators (>= 0: every rod reaches; the arm angle is
    then exact), and 1.0 for linear ones.
    """
    sin, cos, sqrt, asin, atan2 = ops.sin, ops.cos, ops.sqrt, ops.asin, ops.atan2
    fabs, minimum, maximum = ops.abs, ops.minimum, ops.maximum
    free_tx, _, free_tz, _, free_ry, _ = g.kind.axes
    min_length = g.min_length
    rotary = g.kind.rotary
    two_a = 2.0 * g.arm
    rod_minus_arm = g.rod * g.rod - g.arm * g.arm
    arms = g.arm_direction if rotary else ((0.0, 0.0),) * g.legs
    legs = tuple(
        (b[0], b[1], b[2], p[0], p[1], p[2], two_a * d[0], two_a * d[1])
        for b, p, d in zip(g.base, g.platform, arms, strict=True)
    )

    def ik(  # noqa: PLR0917 (the six pose components)
        tx: Any,
        ty: Any,
        tz: Any,
        rx: Any,
        ry: Any,
        rz: Any,
    ) -> tuple[tuple[Any, ...], Any]:
        if not free_tx:
            tx = 0.0
        if not free_tz:
            tz = 0.0
        roll, pitch = rx * DEG, rz * DEG
        ca, sa, cg, sg = cos(roll), sin(roll), cos(pitch), sin(pitch)
        if free_ry:
            yaw = ry * DEG
            cb, sb = cos(yaw), sin(yaw)
        else:
            cb, sb = 1.0, 0.0
        r00, r01, r02 = cb * cg, sb * sa - cb * sg * ca, cb * sg * sa + sb * ca
        r10, r11, r12 = sg, cg * ca, -cg * sa
        r20, r21, r22 = -sb * cg, sb * sg * ca + cb * sa, cb * ca - sb * sg * sa
        out = []
        reach: Any = 1.0
        for bx, by, bz, px, py, pz, ax, az in legs:
            lx = tx + r00 * px + r01 * py + r02 * pz - bx
            ly = ty + r10 * px + r11 * py + r12 * pz - by
            lz = tz + r20 * px + r21 * py + r22 * pz - bz
            if not rotary:
                out.append(sqrt(lx * lx + ly * ly + lz * lz) - min_length)
                continue
            big_l = lx * lx + ly * ly + lz * lz - rod_minus_arm
            m = two_a * ly
            n = ax * lx + az * lz
            ratio = big_l / sqrt(m * m + n * n)
            reach = minimum(reach, 1.0 - fabs(ratio))
            ratio = minimum(maximum(ratio, -1.0), 1.0)
            out.append((asin(ratio) - atan2(n, m)) / DEG)
        return tuple(out), reach

    return ik


MarginFunction = Callable[..., tuple[tuple[Any, ...], Any]]


def make_margin(g: Geometry, ops: Ops) -> MarginFunction:
    """``margin(pose) -> (positions, m)``: ``m`` is the distance to the nearest soft limit as a
    share of that actuator's soft range (0.5 = mid-range), or the rotary reach if smaller;
    ``m >= 0`` means the pose is inside the workspace."""
    ik = make_ik(g, ops)
    minimum = ops.minimum
    limits = tuple((lo, hi, 1.0 / (hi - lo)) for lo, hi in zip(g.lower, g.upper, strict=True))

    def margin(  # noqa: PLR0917 (the six pose components)
        tx: Any,
        ty: Any,
        tz: Any,
        rx: Any,
        ry: Any,
        rz: Any,
    ) -> tuple[tuple[Any, ...], Any]:
        q, m = ik(tx, ty, tz, rx, ry, rz)
        for qi, (lo, hi, inv) in zip(q, limits, strict=True):
            m = minimum(m, minimum(qi - lo, hi - qi) * inv)
        return q, m

    return margin


def _shrink(  # noqa: PLR0917
    margin: MarginFunction, home: Pose, d: tuple[Any, ...], m_home: float, m_out: Any, ops: Ops
) -> Any:
    """The ``lam`` in [0, 1] where ``home + lam d`` first leaves the workspace, from below: the
    first of :data:`SHRINK_SCAN` samples outside brackets it, then Illinois regula falsi.

    ``m_out < 0`` is the margin at ``lam = 1``; the returned ``lam`` always has margin >= 0
    (it only ever moves to points found inside), so the result is inside for any step count.
    """
    where, maximum = ops.where, ops.maximum
    a: Any = 0.0 * m_out
    fa: Any = m_home + a
    b: Any = 1.0 + a
    fb: Any = maximum(m_out, -1.0)  # far outside: a rod's reach can read -30; keep the secant sane
    left: Any = a  # 1 once a sample was outside: the bracket is set
    for k in range(1, SHRINK_SCAN):
        lam = k / SHRINK_SCAN + a * 0.0
        _, f = margin(*(h + lam * di for h, di in zip(home, d, strict=True)))
        f = maximum(f, -1.0)
        first, before = (left < 0.5) & (f < 0.0), (left < 0.5) & (f >= 0.0)
        b, fb = where(first, lam, b), where(first, f, fb)
        a, fa = where(before, lam, a), where(before, f, fa)
        left = where(first, 1.0, left)
    side: Any = 0.0 * a
    for _ in range(SHRINK_STEPS):
        lam = (a * fb - b * fa) / (fb - fa)
        _, f = margin(*(h + lam * di for h, di in zip(home, d, strict=True)))
        f = maximum(f, -1.0)
        inside, outside = f >= 0.0, f < 0.0
        fb = where(inside & (side > 0.0), fb * 0.5, fb)
        fa = where(outside & (side < 0.0), fa * 0.5, fa)
        a, fa = where(inside, lam, a), where(inside, f, fa)
        b, fb = where(inside, b, lam), where(inside, fb, f)
        side = where(inside, 1.0, -1.0)
    return a


@dataclass(frozen=True)
class Workspace:
    """The workspace check and scale-back for one geometry, on floats and on arrays."""

    geometry: Geometry

    def __post_init__(self) -> None:
        g = self.geometry
        object.__setattr__(self, "_margin_scalar", make_margin(g, SCALAR))
        object.__setattr__(self, "_margin_array", make_margin(g, ARRAY))
        _, m_home = self._margin_scalar(*g.home)  # type: ignore[attr-defined]
        if not m_home > 0.0:
            raise ValueError("home is not inside the soft limits")
        object.__setattr__(self, "_m_home", m_home)

    def fit(self, pose: Pose) -> tuple[tuple[float, ...], float]:
        """Actuator positions for ``pose`` (base frame), scaled back toward home if outside.

        Returns ``(positions, lam)``: ``lam = 1`` for a pose inside, else the share of the
        way from home to ``pose`` that was kept (the positions are those of that pose).
        """
        margin = self._margin_scalar  # type: ignore[attr-defined]
        q, m = margin(*pose)
        if m >= 0.0:
            return q, 1.0
        home = self.geometry.home
        d = tuple(p - h for p, h in zip(pose, home, strict=True))
        lam = _shrink(margin, home, d, self._m_home, m, SCALAR)  # type: ignore[attr-defined]
        q, _ = margin(*(h + lam * di for h, di in zip(home, d, strict=True)))
        return q, lam

    def fit_batch(self, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`fit` for ``(N, 6)`` poses: ``(N, legs)`` positions and ``(N,)`` lambdas."""
        poses = np.asarray(poses, dtype=np.float64)
        margin = self._margin_array  # type: ignore[attr-defined]
        q_cols, m = margin(*np.ascontiguousarray(poses.T))
        q = np.empty((poses.shape[0], self.geometry.legs))
        for j, col in enumerate(q_cols):
            q[:, j] = col
        lam = np.ones(poses.shape[0])
        out = np.flatnonzero(m < 0.0)
        if out.size:
            home = np.asarray(self.geometry.home)
            d = poses[out] - home
            lam_out = _shrink(margin, self.geometry.home, tuple(d.T), self._m_home, m[out], ARRAY)  # type: ignore[attr-defined]
            q_out, _ = margin(*(home + lam_out[:, None] * d).T)
            q[out] = np.stack(q_out, axis=1)
            lam[out] = lam_out
        return q, lam


class ForwardKinematicsError(ValueError):
    """Newton's method found no pose for these actuator positions."""


def forward(
    g: Geometry, positions: tuple[float, ...] | list[float], guess: Pose | None = None, tol: float = 1e-13
) -> Pose:
    """The pose whose actuators are at ``positions`` (numerical; for checks, not for the tick).

    Newton's method on the mechanism's free axes with a central-difference Jacobian,
    steps of at most 5 cm / 5 deg, halved until the residual shrinks with every rod in
    reach; stops when a step is below ``tol``. From ``guess`` directly; without one it
    walks the positions from home's in eight stages, so it stays on the assembly mode
    (of the several poses a Stewart platform can take for one set of positions) that
    home belongs to.
    """
    target = np.asarray(positions, dtype=np.float64)
    if guess is not None:
        return _newton(g, np.array(guess, dtype=np.float64), target, tol)
    ik = make_ik(g, SCALAR)
    start = np.asarray(ik(*g.home)[0])
    pose = np.array(g.home, dtype=np.float64)
    for stage in range(1, 9):
        pose = np.asarray(_newton(g, pose, start + stage / 8.0 * (target - start), tol if stage == 8 else 1e-6))
    return tuple(float(v) for v in pose)  # type: ignore[return-value]


def _newton(g: Geometry, pose: FloatArray, target: FloatArray, tol: float) -> Pose:
    ik = make_ik(g, SCALAR)
    free = [i for i, f in enumerate(g.kind.axes) if f]
    limit = np.array([0.05 if axis < 3 else 5.0 for axis in free])  # largest step per iteration (m, deg)

    def residual(p: FloatArray) -> FloatArray:
        q, reach = ik(*p)
        return np.asarray(q) - target if reach >= 0.0 else np.full(g.legs, np.inf)

    h = 1e-6
    f = residual(pose)
    if not np.all(np.isfinite(f)):
        raise ForwardKinematicsError("the starting pose is out of reach")
    for _ in range(100):
        jac = np.empty((g.legs, len(free)))
        for col, axis in enumerate(free):
            up, down = pose.copy(), pose.copy()
            up[axis] += h
            down[axis] -= h
            f_up, f_down = residual(up), residual(down)
            if np.all(np.isfinite(f_up)) and np.all(np.isfinite(f_down)):
                jac[:, col] = (f_up - f_down) / (2.0 * h)
            else:  # at the edge of reach: the one-sided difference that stays inside
                jac[:, col] = (f_up - f) / h if np.all(np.isfinite(f_up)) else (f - f_down) / h
        step = np.linalg.lstsq(jac, -f, rcond=None)[0]
        step *= min(1.0, float(np.min(limit / np.maximum(np.abs(step), 1e-300))))
        for _ in range(40):  # halve until the residual shrinks (or the step is negligible)
            trial = pose.copy()
            trial[free] += step
            f_trial = residual(trial)
            if float(np.linalg.norm(f_trial)) <= float(np.linalg.norm(f)) or float(np.max(np.abs(step))) < tol:
                break
            step *= 0.5
        if not np.all(np.isfinite(f_trial)):
            break
        pose, f = trial, f_trial
        if float(np.max(np.abs(step))) < tol:
            return tuple(float(v) for v in pose)  # type: ignore[return-value]
    raise ForwardKinematicsError(f"no convergence for positions {target.tolist()}")


def axis_ranges(g: Geometry, cap: tuple[float, float] = (1.0, 90.0)) -> tuple[tuple[float, float], ...]:
    """How far each pose axis reaches alone from home, inside the soft limits: ``(down, up)``
    per axis (both >= 0; m for translations, deg for rotations; 0 for an axis the
    mechanism does not move). Bisection to 1e-9 of ``cap`` (1 m, 90 deg)."""
    margin = make_margin(g, SCALAR)
    out: list[tuple[float, float]] = []
    for axis, free in enumerate(g.kind.axes):
        if not free:
            out.append((0.0, 0.0))
            continue
        limit = cap[0] if axis < 3 else cap[1]
        pair = []
        for sign in (-1.0, 1.0):
            lo, hi = 0.0, limit
            pose = list(g.home)
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                pose[axis] = g.home[axis] + sign * mid
                if margin(*pose)[1] >= 0.0:
                    lo = mid
                else:
                    hi = mid
            pair.append(lo)
        out.append((pair[0], pair[1]))
    return tuple(out)
