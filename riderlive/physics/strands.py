"""A strand solver vectorised over strands: Verlet, distance and bending projection, collisions.

Units and frames: metres, seconds, a right-handed world frame with +y up (the rigs'
``tx`` forward, ``ty`` up, ``tz`` side). Positions are stored as ``(V, 3, N)``:
vertex, coordinate, strand, so each vertex of every strand is one contiguous
``(3, N)`` block and one NumPy call works on all strands at once.

Model / State / step: :class:`StrandModel` holds everything static (rest lengths,
masses, stiffness, step size); :class:`StrandState` holds the two position sets
Verlet needs; :func:`step` takes a state and returns a new one without touching its
input. The first ``pinned`` vertices of every strand are kinematic: the caller gives
their positions for the end of the step (the tail's dock, the rider's head).

One step (size ``model.dt``):

1. Verlet with exponential velocity damping and gravity.
2. Pinned vertices are placed.
3. Bending, once: each interior vertex moves part of the way (its strand's
   ``bend``) toward the line through its two neighbours, the neighbours move the
   other way so the centre of mass stays put (the "softer projection" of the post).
4. Distance constraints, ``iterations`` times, in red-black Gauss-Seidel order: the
   even segments together, then the odd ones (segments in one half share no
   vertex, so each half is one vectorised projection).
5. Follow the leader (Mueller et al. 2012): one sweep from root to tip puts each
   vertex at exactly its rest distance from its predecessor, fixing what the few
   Gauss-Seidel iterations left (they converge slowly along an 11-segment chain
   under a hard kick). Its one-sidedness is corrected in the velocities: each vertex
   loses ``leader_correction`` of its child's move.
6. Collision: vertices are projected out of every capsule (a sphere is a capsule
   whose ends coincide); a push deeper than ``REPAIR_DEPTH`` is followed by a distance
   pass and another push, and the last pass leaves no vertex inside.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from riderlive.physics.collision import WEDGE_SKIN, Capsules, push_out

FloatArray = npt.NDArray[np.float64]
EXTRA_PASSES = 32
"""Final collision passes, until no vertex is inside (a vertex wedged between two shapes may need several)."""
MAX_WEDGE_SKIN = 1e-2
"""The largest margin (metres) the final passes grow to for a wedged vertex."""
REPAIR_DEPTH = 3e-4
"""A push deeper than this (metres) is followed by a distance pass to repair the lengths it broke."""
MAX_BEND = 0.5
"""Above this the all-at-once bending pass overshoots (each vertex gets three corrections)."""
GRAVITY = 9.81
"""Standard gravity, m/s^2 (along -y)."""


@dataclass(frozen=True, eq=False)
class StrandModel:
    """Static description of ``N`` strands of ``V`` vertices each.

    ``rest`` is (V-1, N) segment lengths in metres; ``inv_mass`` is (V, N) in 1/kg (the
    pinned vertices' entries are ignored: they are kinematic); ``bend`` is (N,) in
    [0, 0.5], the fraction of the way to the neighbours' line per step; ``damping`` (N,)
    in 1/s; ``dt`` the fixed step in seconds. Scalars broadcast to every strand.
    ``collide_each_iteration`` adds a collision pass after every distance iteration:
    dearer, but short segments resting on a body (the braid on the back) then keep
    their lengths within 1 %.
    """

    rest: FloatArray
    inv_mass: FloatArray | float
    bend: FloatArray | float
    pinned: int = 1
    dt: float = 1.0 / 240.0
    iterations: int = 4
    damping: FloatArray | float = 0.5
    gravity: float = GRAVITY
    collision_passes: int = 2
    leader_correction: float = 1.0
    collide_each_iteration: bool = False
    _pre: dict[str, FloatArray] = field(init=False, repr=False)
    _bends: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rest = np.ascontiguousarray(self.rest, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[0] < 1:
            raise ValueError(f"rest must be (V-1, N), got {rest.shape}")
        n_vert, n_strands = rest.shape[0] + 1, rest.shape[1]
        w = np.array(np.broadcast_to(self.inv_mass, (n_vert, n_strands)), dtype=np.float64)
        bend = np.array(np.broadcast_to(self.bend, (n_strands,)), dtype=np.float64)
        damping = np.array(np.broadcast_to(self.damping, (n_strands,)), dtype=np.float64)
        if not (1 <= self.pinned <= n_vert):
            raise ValueError(f"pinned must be in [1, {n_vert}], got {self.pinned}")
        if np.any(rest <= 0.0) or np.any(w < 0.0) or np.any((bend < 0.0) | (bend > MAX_BEND)):
            raise ValueError(f"rest lengths must be > 0, inverse masses >= 0 and bend in [0, {MAX_BEND}]")
        if not (self.dt > 0.0 and self.iterations >= 1 and np.all(damping >= 0.0)):
            raise ValueError("dt must be > 0, iterations >= 1 and damping >= 0")
        w[: self.pinned] = 0.0
        object.__setattr__(self, "rest", rest)
        object.__setattr__(self, "inv_mass", w)
        object.__setattr__(self, "bend", bend)
        object.__setattr__(self, "damping", damping)
        pre = _precompute(rest, w, bend)
        pre["keep"] = np.exp(-damping * self.dt)
        object.__setattr__(self, "_pre", pre)
        object.__setattr__(self, "_bends", bool(n_vert >= 3 and np.any(bend > 0.0)))

    @property
    def n_vertices(self) -> int:
        return int(self.rest.shape[0]) + 1

    @property
    def n_strands(self) -> int:
        return int(self.rest.shape[1])


def _pair_coefficients(wa: FloatArray, wb: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Shares of a distance correction for the two ends of each segment, (S, 1, N)."""
    total = wa + wb
    safe = np.where(total > 0.0, total, 1.0)
    return (wa / safe)[:, None, :], (wb / safe)[:, None, :]


def _precompute(rest: FloatArray, w: FloatArray, bend: FloatArray) -> dict[str, FloatArray]:
    pre: dict[str, FloatArray] = {}
    for name, first in (("even", 0), ("odd", 1)):
        a = slice(first, -1, 2)
        b = slice(first + 1, None, 2)
        pre[f"{name}_rest"] = np.ascontiguousarray(rest[first::2])
        pre[f"{name}_ca"], pre[f"{name}_cb"] = _pair_coefficients(w[a], w[b])
    # Bending of vertex i toward the line through i-1 and i+1: gradient 1 for i and
    # -1/2 for each neighbour (the nearest point is near the midpoint).
    wa, wb, wc = w[:-2], w[1:-1], w[2:]
    den = wb + 0.25 * (wa + wc)
    safe = np.where(den > 0.0, den, 1.0)
    k = bend[None, :] / safe
    pre["bend_b"] = (k * wb)[:, None, :]
    pre["bend_a"] = (0.5 * k * wa)[:, None, :]
    pre["bend_c"] = (0.5 * k * wc)[:, None, :]
    return pre


@dataclass(frozen=True, eq=False)
class StrandState:
    """Positions now (``x``) and one step ago (``x_prev``), each (V, 3, N), metres."""

    x: FloatArray
    x_prev: FloatArray

    def velocity(self, dt: float) -> FloatArray:
        """The Verlet velocity (x - x_prev) / dt, (V, 3, N) in m/s."""
        return (self.x - self.x_prev) / dt


def rest_state(model: StrandModel, roots: FloatArray, directions: FloatArray) -> StrandState:
    """Straight strands at rest: from ``roots`` (3, N) along unit ``directions`` (3, N)."""
    along = np.vstack([np.zeros((1, model.n_strands)), np.cumsum(model.rest, axis=0)])
    x = roots[None, :, :] + along[:, None, :] * directions[None, :, :]
    return StrandState(x, x.copy())


_ONES3 = np.ones(3)


def _dot3(a: FloatArray, b: FloatArray) -> FloatArray:
    """Dot product over the coordinate axis of (S, 3, N) arrays, (S, N) (a matmul: the cheapest reduction)."""
    out: FloatArray = _ONES3 @ (a * b)
    return out


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
    m -= u  # m is now the offset of b from its nearest point on the line a-c
    b -= pre["bend_b"] * m
    a += pre["bend_a"] * m
    c += pre["bend_c"] * m


def _follow_the_leader(x: FloatArray, rest: FloatArray, pinned: int) -> FloatArray:
    """Put every free vertex at its rest distance from its (already placed) predecessor, root to tip.

    Modifies ``x``; returns the moves (V, 3, N).
    """
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


def step(model: StrandModel, state: StrandState, pins: FloatArray, colliders: Capsules | None = None) -> StrandState:
    """Advance ``state`` by ``model.dt``; ``pins`` (pinned, 3, N) are the kinematic vertices' new positions."""
    x, prev = state.x, state.x_prev
    new = x - prev
    new *= model._pre["keep"]
    new += x
    new[:, 1, :] -= model.gravity * model.dt * model.dt
    new[: model.pinned] = pins
    pre = model._pre
    if model._bends:
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
            _distance_pass(new, pre, "even", 0)  # a deep push broke lengths: repair them...
            if model.n_vertices >= 3:
                _distance_pass(new, pre, "odd", 1)
        wedge = WEDGE_SKIN  # ...and end outside every shape (this pass finds nothing, normally);
        for _ in range(EXTRA_PASSES):  # a vertex wedged between two shapes gets a growing margin
            if push_out(free, caps, wedge) == 0.0:
                break
            wedge = min(2.0 * wedge, MAX_WEDGE_SKIN)
    # Each vertex's velocity loses the part of its child's move that was not its own
    # (Mueller 2012's velocity correction), so the one-sided projection does not add a
    # drag toward the root.
    prev_out = x.copy()
    prev_out[:-1] += model.leader_correction * moves[1:]
    return StrandState(new, prev_out)


def stretch(model: StrandModel, x: FloatArray) -> FloatArray:
    """Relative segment length error |len - rest| / rest, (V-1, N)."""
    d = x[1:] - x[:-1]
    return np.abs(np.sqrt(_dot3(d, d)) / model.rest - 1.0)


def energy(model: StrandModel, state: StrandState) -> float:
    """Kinetic plus gravitational energy of the free vertices, joules.

    Kinetic from the Verlet velocity (x - x_prev)/dt, potential at the current
    positions (under this measure, not the mid-step one, a released strand never
    rises above its starting energy in the tests).
    """
    free = slice(model.pinned, None)
    w = np.asarray(model.inv_mass)[free]
    mass = np.where(w > 0.0, 1.0 / np.where(w > 0.0, w, 1.0), 0.0)
    v = (state.x[free] - state.x_prev[free]) / model.dt
    kinetic = 0.5 * float(np.sum(mass * _dot3(v, v)))
    return kinetic + model.gravity * float(np.sum(mass * state.x[free, 1]))
