"""The subject scheme: who publishes what where, and the version every subject carries.

::

    riderlive.v1.<stage>.<rig>.frame            rig -> engines   one tick: rider + horse + saddle (RLF1 binary or JSON)
    riderlive.v1.<stage>.<rig>.status           rig -> stage     devices, e-stop, rates, heartbeat (JSON, 1 Hz+)
    riderlive.v1.<stage>.<rig>.horse.<producer> producers -> rig horse input, as on /ws/horse (JSON or msgpack)
    riderlive.v1.<stage>.<rig>.saddle.<producer> producers -> rig saddle input, as on /ws/saddle (JSON or msgpack)
    riderlive.v1.<stage>.<rig>.control          request/reply    arm, disarm, reset, reload, estop, state (JSON)
    riderlive.v1.<stage>.estop                  anyone -> all    the stage e-stop: every rig latches
    riderlive.v1.<stage>.heartbeat              stage -> all     the stage heartbeat (the rigs' dead-man input)
    riderlive.v1.<stage>.discover               request/reply    every rig answers with its status (riderlive stage)

The version token (``v1``) changes when the meaning of a subject or of its payload
changes incompatibly. A rig listens on every version of its input subjects
(``riderlive.*.<stage>...``), so a message of another version is *counted*
(``unknown_version``) and answered with an error where there is a reply subject,
never silently lost. An e-stop of any version is obeyed: stopping is never refused.
Stage, rig and producer names are 1-64 of ``A-Z a-z 0-9 _ -``: no dots or wildcards,
so a name can never address someone else's subjects.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

ROOT = "riderlive"
VERSION = "v1"
NAME_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
_NAME = re.compile(NAME_PATTERN)


class Kind(enum.StrEnum):
    """The last fixed token of a subject."""

    FRAME = "frame"
    STATUS = "status"
    HORSE = "horse"
    SADDLE = "saddle"
    CONTROL = "control"
    ESTOP = "estop"
    HEARTBEAT = "heartbeat"
    DISCOVER = "discover"


STAGE_KINDS = frozenset({Kind.ESTOP, Kind.HEARTBEAT, Kind.DISCOVER})
"""Subjects of the whole stage (no rig token)."""
INPUT_KINDS = frozenset({Kind.HORSE, Kind.SADDLE})
"""Producer input subjects: ``...<rig>.<kind>.<producer>`` (one more token)."""


def check_name(value: str, what: str) -> str:
    """``value`` if it is a valid stage/rig/producer name, else ValueError naming ``what``."""
    if not isinstance(value, str) or not _NAME.fullmatch(value):  # `$` alone accepts a trailing newline
        raise ValueError(f"{what} {value!r} must be 1-64 characters of A-Z a-z 0-9 _ - (no dots, no spaces)")
    return value


@dataclass(frozen=True)
class Stage:
    """The subjects of one stage (and of its rigs), of one version."""

    name: str
    version: str = VERSION

    def __post_init__(self) -> None:
        check_name(self.name, "stage")

    def _base(self, version: str | None = None) -> str:
        return f"{ROOT}.{self.version if version is None else version}.{self.name}"

    def subject(self, kind: Kind, version: str | None = None) -> str:
        """A stage-wide subject; ``version="*"`` for a subscription to every version."""
        assert kind in STAGE_KINDS
        return f"{self._base(version)}.{kind.value}"

    def rig(self, rig: str) -> RigSubjects:
        return RigSubjects(self, check_name(rig, "rig"))

    def every_rig(self, kind: Kind) -> str:
        """A subscription to one kind of subject of every rig (``...*.status``)."""
        return f"{self._base()}.*.{kind.value}"


@dataclass(frozen=True)
class RigSubjects:
    stage: Stage
    rig: str

    def subject(self, kind: Kind, version: str | None = None) -> str:
        assert kind not in STAGE_KINDS and kind not in INPUT_KINDS
        return f"{self.stage._base(version)}.{self.rig}.{kind.value}"

    def input(self, kind: Kind, producer: str, version: str | None = None) -> str:
        """Producer ``producer``'s input subject of ``kind`` (horse or saddle)."""
        assert kind in INPUT_KINDS
        return f"{self.stage._base(version)}.{self.rig}.{kind.value}.{check_name(producer, 'producer')}"

    def input_any(self, kind: Kind) -> str:
        """Every producer's input subject of ``kind``, of every version."""
        assert kind in INPUT_KINDS
        return f"{self.stage._base('*')}.{self.rig}.{kind.value}.*"

    def horse(self, producer: str, version: str | None = None) -> str:
        return self.input(Kind.HORSE, producer, version)

    def saddle(self, producer: str, version: str | None = None) -> str:
        return self.input(Kind.SADDLE, producer, version)

    def horse_any(self) -> str:
        """Every producer's horse subject, of every version."""
        return self.input_any(Kind.HORSE)

    def saddle_any(self) -> str:
        """Every producer's saddle subject, of every version."""
        return self.input_any(Kind.SADDLE)


@dataclass(frozen=True)
class Parsed:
    """A subject taken apart: version, stage, rig ("" for stage subjects), kind, producer."""

    version: str
    stage: str
    rig: str
    kind: str
    producer: str = ""

    @property
    def known_version(self) -> bool:
        return self.version == VERSION


def parse(subject: str) -> Parsed | None:
    """A riderlive subject taken apart, or None for anything else."""
    parts = subject.split(".")
    if len(parts) < 4 or parts[0] != ROOT:
        return None
    if len(parts) == 4:
        return Parsed(parts[1], parts[2], "", parts[3])
    if len(parts) == 5:
        return Parsed(parts[1], parts[2], parts[3], parts[4])
    if len(parts) == 6 and parts[4] in INPUT_KINDS:
        return Parsed(parts[1], parts[2], parts[3], parts[4], parts[5])
    return None
