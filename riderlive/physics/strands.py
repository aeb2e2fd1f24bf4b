"""The strand solver: Verlet, distance and bending projection, follow-the-leader, collisions (compiled).

Units and frames: metres, seconds, a right-handed world frame with +y up (the rigs'
``tx`` forward, ``ty`` up, ``tz`` side). Positions are stored as ``(V, 3, N)``:
vertex, coordinate, strand; the kernels loop over vertices, then strands (innermost,
contiguous), so 2 strands or 4000 run the same code. Written once, as loops, and
compiled (:mod:`riderlive.fastpath`); ``advance.py_func`` runs the same source
interpreted (tests).

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
   even segments, then the odd ones (segments in one half share no vertex, so the
   order within a half does not matter).
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

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import kernel
from riderlive.physics.collision import SKIN, WEDGE_SKIN, Capsules, push_out
from riderlive.physics.vec3 import fmax

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
    their lengths within 1 %. Derived: ``keep`` (N,), the velocity kept per step
    ``exp(-damping dt)``; ``bends``, whether any strand bends.
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
    keep: FloatArray = field(init=False, repr=False)
    bends: bool = field(init=False, repr=False)

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
        object.__setattr__(self, "keep", np.exp(-damping * self.dt))
        object.__setattr__(self, "bends", bool(n_vert >= 3 and np.any(bend > 0.0)))

    @property
    def n_vertices(self) -> int:
        return int(self.rest.shape[0]) + 1

    @property
    def n_strands(self) -> int:
        return int(self.rest.shape[1])

    @property
    def solver(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, int, int, int, bool, bool, float, float]:
        """The arguments :func:`advance` takes after the positions, pins and colliders."""
        return (
            self.rest,
            np.asarray(self.inv_mass),
            np.asarray(self.bend),
            self.keep,
            int(self.pinned),
            int(self.iterations),
            int(self.collision_passes),
            self.bends,
            bool(self.collide_each_iteration),
            float(self.gravity * self.dt * self.dt),
            float(self.leader_correction),
        )


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


_NO_CAPS = Capsules.empty()


def step(model: StrandModel, state: StrandState, pins: FloatArray, colliders: Capsules | None = None) -> StrandState:
    """Advance ``state`` by ``model.dt``; ``pins`` (pinned, 3, N) are the kinematic vertices' new positions."""
    caps = _NO_CAPS if colliders is None else colliders
    new, prev = advance(state.x, state.x_prev, pins, caps.a, caps.b, caps.radius, *model.solver)
    return StrandState(new, prev)


# ----------------------------------------------------------------------------- the kernels


@kernel
def advance(  # noqa: PLR0917
    x: FloatArray,
    prev: FloatArray,
    pins: FloatArray,
    cap_a: FloatArray,
    cap_b: FloatArray,
    cap_r: FloatArray,
    rest: FloatArray,
    w: FloatArray,
    bend: FloatArray,
    keep: FloatArray,
    pinned: int,
    iterations: int,
    collision_passes: int,
    bends: bool,
    collide_each: bool,
    fall: float,
    leader: float,
) -> tuple[FloatArray, FloatArray]:
    """One step (see the module docstring): new positions and the new previous positions, (V, 3, N) each.

    Colliders: capsule ends ``cap_a``, ``cap_b`` (K, 3), radii ``cap_r`` (K,); the rest is
    :attr:`StrandModel.solver` (``fall`` is gravity * dt * dt).
    """
    n_vert, _, n = x.shape
    new = np.empty_like(x)
    for i in range(n_vert):  # Verlet with damping, and gravity
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
        bend_pass(new, w, bend)
    caps = cap_r.shape[0] > 0
    for _ in range(iterations):
        distance_pass(new, rest, w, 0)
        distance_pass(new, rest, w, 1)
        if caps and collide_each:
            push_out(new, pinned, cap_a, cap_b, cap_r, SKIN)
    moves = follow_the_leader(new, rest, pinned)
    if caps:
        for _ in range(collision_passes):
            if push_out(new, pinned, cap_a, cap_b, cap_r, SKIN) < REPAIR_DEPTH:
                break
            distance_pass(new, rest, w, 0)  # a deep push broke lengths: repair them...
            distance_pass(new, rest, w, 1)
        wedge = WEDGE_SKIN  # ...and end outside every shape (this pass finds nothing, normally);
        for _ in range(EXTRA_PASSES):  # a vertex wedged between two shapes gets a growing margin
            if push_out(new, pinned, cap_a, cap_b, cap_r, wedge) == 0.0:
                break
            wedge = min(2.0 * wedge, MAX_WEDGE_SKIN)
    # Each vertex's velocity loses the part of its child's move that was not its own
    # (Mueller 2012's velocity correction), so the one-sided projection does not add a
    # drag toward the root.
    out_prev = x.copy()
    for i in range(n_vert - 1):
        for c in range(3):
            for s in range(n):
                out_prev[i, c, s] += leader * moves[i + 1, c, s]
    return new, out_prev


@kernel
def distance_pass(x: FloatArray, rest: FloatArray, w: FloatArray, first: int) -> None:
    """Project segments ``first``, ``first + 2``, ... to their rest lengths, shared by inverse mass."""
    n_vert, _, n = x.shape
    for i in range(first, n_vert - 1, 2):
        for s in range(n):
            wa, wb = w[i, s], w[i + 1, s]
            total = wa + wb
            safe = total if total > 0.0 else 1.0
            d0 = x[i + 1, 0, s] - x[i, 0, s]
            d1 = x[i + 1, 1, s] - x[i, 1, s]
            d2 = x[i + 1, 2, s] - x[i, 2, s]
            f = 1.0 - rest[i, s] / fmax(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2), 1e-12)
            d0, d1, d2 = d0 * f, d1 * f, d2 * f
            ca, cb = wa / safe, wb / safe
            x[i, 0, s] += ca * d0
            x[i, 1, s] += ca * d1
            x[i, 2, s] += ca * d2
            x[i + 1, 0, s] -= cb * d0
            x[i + 1, 1, s] -= cb * d1
            x[i + 1, 2, s] -= cb * d2


@kernel
def bend_pass(x: FloatArray, w: FloatArray, bend: FloatArray) -> None:
    """Move each interior vertex part of the way toward its neighbours' line, the neighbours the other way.

    Every correction is computed from the same positions, then applied: the middle
    vertices first, then the first neighbours, then the second ones (gradient 1 for
    the vertex, -1/2 for each neighbour: the nearest point is near the midpoint).
    """
    n_vert, _, n = x.shape
    m = np.empty((n_vert - 2, 3, n))  # offsets of each vertex from its neighbours' line
    k = np.empty((n_vert - 2, 3, n))  # shares of the first neighbour, the vertex, the second neighbour
    for i in range(n_vert - 2):
        for s in range(n):
            u0, u1, u2 = x[i + 2, 0, s] - x[i, 0, s], x[i + 2, 1, s] - x[i, 1, s], x[i + 2, 2, s] - x[i, 2, s]
            m0, m1, m2 = x[i + 1, 0, s] - x[i, 0, s], x[i + 1, 1, s] - x[i, 1, s], x[i + 1, 2, s] - x[i, 2, s]
            t = (m0 * u0 + m1 * u1 + m2 * u2) / fmax(u0 * u0 + u1 * u1 + u2 * u2, 1e-18)
            m[i, 0, s], m[i, 1, s], m[i, 2, s] = m0 - u0 * t, m1 - u1 * t, m2 - u2 * t
            wa, wb, wc = w[i, s], w[i + 1, s], w[i + 2, s]
            den = wb + 0.25 * (wa + wc)
            kk = bend[s] / (den if den > 0.0 else 1.0)
            k[i, 0, s], k[i, 1, s], k[i, 2, s] = 0.5 * kk * wa, kk * wb, 0.5 * kk * wc
    for i in range(n_vert - 2):
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


@kernel
def follow_the_leader(x: FloatArray, rest: FloatArray, pinned: int) -> FloatArray:
    """Put every free vertex at its rest distance from its (already placed) predecessor, root to tip.

    Modifies ``x``; returns the moves (V, 3, N).
    """
    n_vert, _, n = x.shape
    moves = np.zeros_like(x)
    for i in range(pinned, n_vert):
        for s in range(n):
            d0 = x[i, 0, s] - x[i - 1, 0, s]
            d1 = x[i, 1, s] - x[i - 1, 1, s]
            d2 = x[i, 2, s] - x[i - 1, 2, s]
            f = rest[i - 1, s] / math.sqrt(fmax(d0 * d0 + d1 * d1 + d2 * d2, 1e-24)) - 1.0
            for c, d in ((0, d0), (1, d1), (2, d2)):
                before = x[i, c, s]
                x[i, c, s] += d * f
                moves[i, c, s] = x[i, c, s] - before
    return moves


# ----------------------------------------------------------------------------- diagnostics (NumPy)


def stretch(model: StrandModel, x: FloatArray) -> FloatArray:
    """Relative segment length error |len - rest| / rest, (V-1, N)."""
    d = x[1:] - x[:-1]
    return np.asarray(np.abs(np.sqrt(np.einsum("icn,icn->in", d, d)) / model.rest - 1.0), dtype=np.float64)


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
    kinetic = 0.5 * float(np.sum(mass * np.einsum("icn,icn->in", v, v)))
    return kinetic + model.gravity * float(np.sum(mass * state.x[free, 1]))
