"""The rider leading the horse (thesis section 10): a take scripted as the rider's aids.

Section 10 proposes "a simulation where the user could animate the rider's directional
commands and the horse would automatically be simulated according to that input". An
aid script (TOML) lists the rider's aids by time; the horse answers each one as a horse
does, and the take is compiled into the shot script segments the procedural horse
already plays (:class:`~riderlive.horse.script.ShotScript`)::

    name = "a hack"
    seconds = 30        # the take's length
    start = "halt"      # optional: the gait at t = 0 (default halt: standing)

    [response]          # optional: how the horse answers (defaults below)
    delay = 0.3         # s from the aid to the horse's answer
    acceleration = 2.0  # m/s^2: bound on the ground speed's rate of change
    speed_step = 0.25   # 'faster' / 'slower': this fraction of the gait's speed range

    [[aid]]
    at = 1.0            # s
    aid = "walk on"     # walk on, trot, canter, gallop, halt, faster, slower, jump

An aid at ``t`` changes nothing before ``t + delay``. Then a gait aid blends into the
new gait over one stride of it (``model``: 0.4-1.2 s) while the ground speed ramps
to the gait's default speed with ``|dv/dt| <= acceleration``; ``faster`` / ``slower``
change the speed within the gait by ``speed_step`` of its range (clamped to it), and
``halt`` brings the horse to a stand, both within the same bound; ``jump`` performs the
jump from the current gait, which returns to it (the jump keeps its own speed profile).
The horse goes straight (it has no turning), so there are no turning aids. Figures:
``docs/horse.md``, "Aids".
"""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Any, Self

import pydantic

from riderlive.configfile import StrictModel, read_toml, validate
from riderlive.horse.gaits import GAIT_TABLE, Gait, parse_gait
from riderlive.horse.model import target_speed
from riderlive.horse.script import Segment, ShotScript, TakeHeader, load_script


class Aid(enum.Enum):
    """The rider's aids the procedural horse answers."""

    WALK_ON = "walk on"
    TROT = "trot"
    CANTER = "canter"
    GALLOP = "gallop"
    HALT = "halt"
    FASTER = "faster"
    SLOWER = "slower"
    JUMP = "jump"


AIDS: tuple[str, ...] = tuple(a.value for a in Aid)
"""Every aid's name, in the order the docs list them."""
_GAIT_OF: dict[Aid, Gait] = {
    Aid.WALK_ON: Gait.WALK,
    Aid.TROT: Gait.TROT,
    Aid.CANTER: Gait.CANTER,
    Aid.GALLOP: Gait.GALLOP,
    Aid.HALT: Gait.HALT,
}

REACTION_DELAY = 0.3
"""Seconds from an aid to the horse's answer (the project's choice, see ``docs/horse.md``)."""
ACCELERATION = 2.0
"""m/s^2: the bound on the ground speed's rate of change under the aids (the project's choice)."""
SPEED_STEP = 0.25
"""'faster' / 'slower': the fraction of the gait's speed range one aid asks for."""


class Response(StrictModel):
    """How the horse answers an aid: delay (s), speed change bound (m/s^2), speed step (fraction)."""

    delay: float = pydantic.Field(default=REACTION_DELAY, ge=0.05, le=2.0)
    acceleration: float = pydantic.Field(default=ACCELERATION, ge=0.2, le=10.0)
    speed_step: float = pydantic.Field(default=SPEED_STEP, gt=0.0, le=1.0)


class TimedAid(StrictModel):
    """One aid: ``aid`` (a name of :data:`AIDS`) given at ``at`` seconds."""

    at: float = pydantic.Field(ge=0.0, le=3600.0)
    aid: str

    @pydantic.field_validator("aid")
    @classmethod
    def _known(cls, value: str) -> str:
        if value not in AIDS:
            raise ValueError(f"unknown aid {value!r}: the horse answers {', '.join(repr(a) for a in AIDS)}")
        return value


class AidScript(TakeHeader):
    """A take as the rider's aids; :meth:`shot` is the equivalent shot script."""

    seconds: float = pydantic.Field(gt=0.0, le=3600.0)
    start: str = "halt"
    response: Response = Response()
    aid: list[TimedAid] = pydantic.Field(min_length=1, max_length=10_000)

    @pydantic.field_validator("start")
    @classmethod
    def _gait(cls, value: str) -> str:
        parse_gait(value)  # ValueError naming the gaits
        return value

    @pydantic.model_validator(mode="after")
    def _plan(self) -> Self:
        self.segments()  # an aid the horse cannot answer is refused at load
        return self

    def segments(self) -> list[Segment]:
        """The aids as back-to-back segments: each answer starts ``response.delay`` after its aid.

        ValueError (naming the aid by its index) for aids out of time order and for
        ``faster``, ``slower`` or ``jump`` while the horse stands.
        """
        r = self.response
        gait = parse_gait(self.start)
        speed = target_speed(gait, None)
        answers: list[tuple[float, dict[str, Any]]] = []
        last = 0.0
        for i, entry in enumerate(self.aid):
            if entry.at < last:
                raise ValueError(f"aid {i}: at = {entry.at!r} s comes before aid {i - 1}'s {last!r} s")
            last = entry.at
            aid = Aid(entry.aid)
            if gait is Gait.HALT and aid in (Aid.FASTER, Aid.SLOWER, Aid.JUMP):
                raise ValueError(f"aid {i}: {aid.value!r} while the horse stands: ask for a gait first")
            if aid is Aid.JUMP:
                answer: dict[str, Any] = {"move": "jump"}
            elif aid in (Aid.FASTER, Aid.SLOWER):
                lo, hi = GAIT_TABLE[gait].speed
                step = r.speed_step * (hi - lo) * (1.0 if aid is Aid.FASTER else -1.0)
                speed = min(max(speed + step, lo), hi)
                answer = {"gait": gait.value, "speed": speed, "accel": r.acceleration}
            else:
                gait = _GAIT_OF[aid]
                speed = target_speed(gait, None)
                answer = {"gait": gait.value, "accel": r.acceleration}
            at = entry.at + r.delay
            if at >= self.seconds:
                break  # answered after the take's end
            if answers and answers[-1][0] == at:
                answers.pop()  # two aids at once: the later one is answered
            answers.append((at, answer))
        starts = [0.0] + [at for at, _ in answers]
        ends = [*starts[1:], self.seconds]
        plans = [{"gait": self.start}] + [answer for _, answer in answers]
        return [Segment(**plan, seconds=end - begin) for plan, begin, end in zip(plans, starts, ends, strict=True)]

    def shot(self) -> ShotScript:
        """The equivalent shot script (same header: name, seed, variation, terrain)."""
        header = self.model_dump(include=set(TakeHeader.model_fields))
        return ShotScript(**header, segment=self.segments())


def load_take(path: str | Path) -> ShotScript:
    """A scripted take from TOML: an aid script (it has ``[[aid]]``) compiled to its shot
    script, else a shot script; errors name the file and key (``aid.2.aid: unknown aid``)."""
    data = read_toml(path)
    if isinstance(data, dict) and "aid" in data:
        return validate(AidScript, data, str(path)).shot()
    return load_script(path)
