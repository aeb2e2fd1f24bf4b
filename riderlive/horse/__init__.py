"""The procedural horse: gaits and movements on demand, live or as a whole take.

- ``DEFAULT_SCALE``: thesis rig units per metre. With it the foot-height clamps of
  Appendix B (hoof height sums 15, 18, 20) stay idle in the walk and the trot and
  engage in the jump and the rear (``docs/horse.md``).
- ``GAITS`` (walk, trot, canter, gallop) and ``MOVES`` (jump, rear, stop, buck); the
  API takes names (strings) and also accepts ``halt`` (standing).
- ``ProceduralHorse(gait="trot", speed=None, seed=None, terrain=None)``: a live source
  (``terrain``: a :class:`Terrain`, the ground it runs on; None: flat and level).
  ``sample(t)`` returns one frame in ``channels.HORSE`` order (metres, degrees) for
  ``t`` in seconds, non-decreasing; ``set_gait(gait, speed=None)`` changes gait or
  speed at any time, ``perform(move)`` starts a movement from the current state,
  ``play(script)`` follows a :class:`ShotScript` from now on; ``set_terrain(terrain)``
  changes the ground ahead (:func:`riderlive.horse.terrain.join`); ``gait``, ``move`` and
  ``speed`` (m/s) report what it is doing. Every channel stays C1
  across every change. A seed turns on seeded stride-to-stride variation.
- ``generate(script, rate)`` / ``generate_gait(gait, seconds, rate)``: a whole take as
  a :class:`riderlive.framefile.FrameTable` (NumPy, same numbers as the live path).
- The pure core is :mod:`riderlive.horse.model` (Model / State / step, no clocks).

Frames: hoof ``tx`` forward (+) of the hoof's square-standing spot, ``ty`` height above
the ground, ``tz`` side (+ to the horse's right: the rig is right-handed, +X forward,
+Y up); ``rearPivot.t*`` the hips' displacement from standing, ``rearPivot.rz`` pitch
(+ nose up), ``rx`` roll (+ rolling right), ``ry`` yaw (+ left); ``backMid.rz`` the
back's bend; ``root.tx`` distance travelled, ``root.tz/ry`` 0 (a straight path). On flat
ground ``root.ty`` and ``ground.*`` are 0; on a :class:`Terrain` ``root.tx/ty`` are the
world position, ``ground.rz`` the ground's pitch (in ``rearPivot.rz`` too) and ``ground.ty``
its height (``riderlive.horse.terrain``).
"""

from __future__ import annotations

from dataclasses import replace

from riderlive.framefile import FrameTable
from riderlive.horse.curves import SCALAR
from riderlive.horse.gaits import GAIT_TABLE, GAITS, WITHERS_HEIGHT, Gait, parse_gait
from riderlive.horse.model import Model, Perform, SetGait, State, command, initial, step, target_speed, unschedule
from riderlive.horse.moves import MOVE_TABLE, MOVES, Move, parse_move
from riderlive.horse.script import DEFAULT_VARIATION, ShotScript, gait_script, generate, load_script
from riderlive.horse.terrain import Terrain, TerrainConfig, join
from riderlive.units import RIG_UNITS_PER_METRE

DEFAULT_SCALE = RIG_UNITS_PER_METRE
"""The default ``length_scale``: thesis rig units per metre (a 1.6 m horse is 40 units tall at
the withers), so the service speaks metres; the number's one source is ``riderlive.units``."""

__all__ = [
    "DEFAULT_SCALE",
    "GAITS",
    "GAIT_TABLE",
    "MOVES",
    "MOVE_TABLE",
    "WITHERS_HEIGHT",
    "Gait",
    "Move",
    "ProceduralHorse",
    "ShotScript",
    "Terrain",
    "TerrainConfig",
    "gait_speed",
    "generate",
    "generate_gait",
    "load_script",
]


def gait_speed(gait: str, speed: float | None = None) -> float:
    """The ground speed (m/s) ``gait`` (a name, ``halt`` too) runs at: its default when
    ``speed`` is None, else ``speed`` if the gait allows it (ValueError naming the range)."""
    return target_speed(parse_gait(gait), speed)


def generate_gait(
    gait: str, seconds: float, rate: float = 120.0, speed: float | None = None, seed: int | None = None
) -> FrameTable:
    """``gait`` held for ``seconds`` at ``rate`` Hz, as a FrameTable."""
    return generate(gait_script(gait, seconds, speed, seed), rate)


class ProceduralHorse:
    """A live horse source: one frame per :meth:`sample`; commands take effect at the last sample's time."""

    def __init__(
        self,
        gait: str = "trot",
        speed: float | None = None,
        seed: int | None = None,
        variation: float | None = None,
        terrain: Terrain | None = None,
    ) -> None:
        if variation is None:
            variation = DEFAULT_VARIATION if seed is not None else 0.0
        self.model = Model(variation=variation, seed=seed or 0, terrain=terrain)
        self._start = (parse_gait(gait), speed)
        initial(self.model, *self._start)  # validates gait and speed now
        self._state: State | None = None
        self._t = 0.0  # time of the last sample (s)
        self._queued: list[SetGait | Perform | ShotScript] = []

    @property
    def state(self) -> State | None:
        """The pure core's state (None before the first sample)."""
        return self._state

    @property
    def gait(self) -> str:
        return (self._state.gait if self._state else self._start[0]).value

    @property
    def speed(self) -> float:
        """Ground speed (m/s) at the last sample."""
        if self._state is None:
            return initial(self.model, *self._start).gait_speed
        v, _, _ = self._state.ramp.at(self._t, SCALAR)
        return float(v)

    @property
    def move(self) -> str | None:
        return self._state.move.value if self._state and self._state.move else None

    def sample(self, t: float) -> list[float]:
        """The frame at ``t`` (s): ``len(channels.HORSE)`` floats, metres and degrees."""
        t = float(t)
        if self._state is None:
            self._state = initial(self.model, *self._start, t=t)
            self._t = t
            for queued in self._queued:
                self._apply(queued)
            self._queued.clear()
        elif not t >= self._t:
            raise ValueError(f"time went backwards or is not finite: {t!r} after {self._t!r}")
        self._t = t
        self._state, out = step(self.model, self._state, t)
        return out

    def set_gait(self, gait: str, speed: float | None = None) -> None:
        """Change gait and/or speed (m/s, within the gait's range) from now, C1; ends a playing script."""
        g = parse_gait(gait)
        self._apply(SetGait(g, None if speed is None else float(speed)), validate=True)

    def perform(self, move: str) -> None:
        """Start a movement (jump, rear, stop, buck) from the current state; ends a playing script."""
        self._apply(Perform(parse_move(move)))

    def play(self, script: ShotScript) -> None:
        """Follow ``script`` from now: its segments replace whatever was queued."""
        self._apply(script)

    def set_terrain(self, terrain: Terrain | None) -> float:
        """Change the ground to ``terrain`` (None: flat and level) from the last sample on: the
        ground under the horse stays, the slope eases into the new one over ``TRANSITION`` m
        (:func:`~riderlive.horse.terrain.join`), so position and pitch stay C1. Returns the
        distance travelled (m) where the new ground's distance 0 lies (0 before the first sample)."""
        if self._state is None:
            self.model = replace(self.model, terrain=terrain)
            return 0.0
        at = self._state.x0 + float(self._state.ramp.at(self._t, SCALAR)[2])
        joined, start = join(self.model.terrain, terrain, at)
        self.model = replace(self.model, terrain=joined)
        return start

    def _apply(self, cmd: SetGait | Perform | ShotScript, validate: bool = False) -> None:
        if validate and isinstance(cmd, SetGait) and cmd.speed is not None and cmd.gait in GAIT_TABLE:
            GAIT_TABLE[cmd.gait].check_speed(cmd.speed)
        if self._state is None:
            self._queued.append(cmd)
            return
        state = unschedule(self._state)  # a new command or script replaces a script in progress
        if isinstance(cmd, ShotScript):
            self._state = cmd.start(self.model, self._t, state)
        else:
            self._state = command(self.model, state, cmd, self._t)
