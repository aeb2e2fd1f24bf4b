"""The operator's side of ``riderlive rig --drive`` (``riderlive/rig_drive.py``): what the web
process is to ``serve``'s tick, in a thread beside the tick loop.

:class:`Operator` reads the tick's status blob, sends its requests on the command pipe (the
arm once the rig is first disarmed, with ``--arm`` only; the disarm when the drive's time is
up, counted from the arm; the stop), keeps the guardian and its standby
(``devices/guardians.py``) and says what happens: who watches, each guardian loss the tick
counts (it parks the rig), a summary once a second. How the drive ended is an
:class:`Ending` with its exit status. Times are ``perf_counter`` seconds.
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import orjson

from riderlive.devices.guardians import Guardians
from riderlive.devices.lifecycle import DeviceState
from riderlive.devices.registry import DeviceSpec
from riderlive.realtime import commands as cmd
from riderlive.realtime.counters import TickCounters
from riderlive.realtime.memory import TickMemory

log = logging.getLogger("riderlive.rig")
S = DeviceState
Say = Callable[[str], None]
ESTOP_READBACK_S = 5.0
"""After an e-stop, how long the torque-off read-back is waited for before exiting anyway."""
POLL_S = 0.01
"""How often the operator thread looks at the tick's status and the guardians."""
EXIT_FAULT, EXIT_ESTOP = 1, 130


class Ending(enum.Enum):
    """How a drive ended, and its exit status."""

    LEFT_DISARMED = "left disarmed"
    PARKED = "parked"
    FAULT = "fault"
    UNASKED_STOP = "stopped without being asked"
    ESTOP = "e-stop"

    @property
    def exit_code(self) -> int:
        return {Ending.ESTOP: EXIT_ESTOP, Ending.FAULT: EXIT_FAULT, Ending.UNASKED_STOP: EXIT_FAULT}.get(self, 0)


class Phase(enum.Enum):
    """The operator's side of a drive."""

    CONNECTING = "connecting"
    """Until the rig is first disarmed."""
    ARMING = "arming"
    """The arm request sent, its reply awaited."""
    DRIVING = "driving"
    """Armed: the time runs."""
    PARKING = "parking"
    """The time is up: the disarm sent."""
    STOPPING = "stopping"
    """The stop sent: the loop ends once the rig rests."""


@dataclass(frozen=True)
class DrivePlan:
    """What to drive and how: the rig's device, for ``seconds`` once armed, armed or not."""

    spec: DeviceSpec
    seconds: float
    arm: bool


class Operator:
    """The operator's side of the tick (what the web process is to ``serve``'s tick): reads
    its status blob, sends requests on the command pipe, keeps the guardians; one thread."""

    def __init__(
        self, memory: TickMemory, commands: Connection, plan: DrivePlan, guardians: Guardians | None, say: Say
    ) -> None:
        self.memory = memory
        self.commands = commands
        self.spec, self.seconds, self.arm = plan.spec, plan.seconds, plan.arm
        self.guardians = guardians
        self.say = say
        self.counters = TickCounters(memory.counters.values)
        self.phase = Phase.CONNECTING
        self.ending: Ending | None = None
        self.rig: dict[str, Any] = {}
        """The rig's last status (``DeviceStatus.to_dict``)."""
        self.why = ""
        """Why a drive ended unasked (a refused arm, the guardian lost)."""
        self.done = threading.Event()
        self._version = -1
        self._armed_at = 0.0
        self._estop_at: float | None = None
        self._guardian_lost: str | None = None
        self._losses = 0
        self._watching: tuple[int | None, int | None] = (None, None)
        self._next_print = 0.0
        self.start = time.perf_counter()

    def run(self) -> None:
        """Until the loop has ended (``done``); a failure of its own stops the tick."""
        try:
            while not self.done.wait(POLL_S):
                self.step(time.perf_counter())
        except Exception:
            log.exception("the operator thread failed: stopping the tick")
            self._stop(Ending.FAULT)

    def step(self, now: float) -> None:
        """One look: the guardians, the requests' replies, the status."""
        if self.guardians is not None:
            self.guardians.check(now)
            self._say_guardians()
        for reply in self._replies():
            self._on_reply(reply, now)
        status = self._status()
        if status is None or not status.get("rig"):
            return
        self.rig = status["rig"]
        self._say_guardian_watch(status.get("guardian"))
        self._decide(DeviceState(self.rig["state"]), now)
        if now >= self._next_print:
            self._next_print = now + 1.0
            self.say(self._summary(now))

    def _decide(self, state: DeviceState, now: float) -> None:
        phase = self.phase
        if phase is Phase.STOPPING:
            return
        if state is S.ESTOP:
            self._estop_at = now if self._estop_at is None else self._estop_at
            if self.rig["outputs_off_confirmed"] or now - self._estop_at > ESTOP_READBACK_S:
                self._stop(Ending.ESTOP)
        elif state is S.FAULT:
            self._stop(Ending.FAULT)
        elif phase is Phase.CONNECTING and state is S.DISARMED:
            if not self.arm:
                self.say("disarmed: connected, checked, configured, torque off. Nothing moves without --arm.")
                self._stop(Ending.LEFT_DISARMED)
            else:
                self.phase = Phase.ARMING
                self.commands.send(cmd.Arm(self.spec.name, "cli --arm", 1))
        elif phase is Phase.DRIVING and state is S.PARKED:
            self.why = f"parked by the tick: {self._guardian_lost or 'not asked by this command'}"
            self._stop(Ending.UNASKED_STOP)
        elif phase is Phase.PARKING and state is S.PARKED:
            self._stop(Ending.PARKED)
        elif phase is Phase.DRIVING and now - self._armed_at >= self.seconds:
            self.phase = Phase.PARKING
            self.commands.send(cmd.Disarm(self.spec.name, "cli: time is up", 2))

    def _on_reply(self, reply: cmd.Reply, now: float) -> None:
        if reply.request != 1 or self.phase is not Phase.ARMING:
            return
        if reply.ok:
            self.phase, self._armed_at = Phase.DRIVING, now
        else:
            self.why = f"not armed: {reply.message}"
            self.say(self.why)
            self._stop(Ending.UNASKED_STOP)

    def _stop(self, ending: Ending) -> None:
        if self.phase is Phase.STOPPING:
            return
        self.phase, self.ending = Phase.STOPPING, ending
        self.commands.send(cmd.Stop())

    def _replies(self) -> list[cmd.Reply]:
        out = []
        while self.commands.poll():
            message = self.commands.recv()
            if isinstance(message, cmd.Reply):
                out.append(message)
        return out

    def _status(self) -> dict[str, Any] | None:
        blob = self.memory.status_blob
        version = blob.version
        if version == self._version:
            return None
        data = blob.read()
        if data is None:
            return None
        self._version = version
        status: dict[str, Any] = orjson.loads(data)
        return status

    def _say_guardians(self) -> None:
        """Say who watches when it changes (a standby that took over, a new standby)."""
        guardians = self.guardians
        assert guardians is not None
        standby = guardians.standby
        watching = (
            None if guardians.guardian is None else guardians.guardian.pid,
            None if standby is None or standby.poll() is not None else standby.pid,
        )
        if watching != self._watching:
            self._watching = watching
            self.say(f"guardian {watching[0]} watches; standby {watching[1] or 'none'}")

    def _say_guardian_watch(self, guardian: dict[str, Any] | None) -> None:
        """The tick's own watch of the guardian: each loss it counts (it parks the rig; a
        guardian replaced by its standby between two looks counts too, though none is missing)."""
        if guardian is None:
            return
        lost = guardian.get("lost")
        if guardian["losses"] > self._losses:
            self._losses = guardian["losses"]
            self._guardian_lost = lost or "the guardian that watched was replaced by its standby"
            self.say(f"the tick lost its guardian: {self._guardian_lost} (it parks the rig; arming is refused)")

    def _summary(self, now: float) -> str:
        rig = self.rig
        servos = rig.get("servos") or []
        errors = [abs(s["tracking_error_deg"]) for s in servos if s["tracking_error_deg"] is not None]
        temps = [s["temperature_c"] for s in servos if s["temperature_c"] is not None]
        return (
            f"{now - self.start:7.2f} s  {rig['state']:12s} clamps {rig.get('clamps', 0):2d}  "
            f"max tracking error {max(errors, default=0.0):5.2f} deg  max temperature {max(temps, default=0)} C  "
            f"overruns {self.counters.overruns}"
        )


def said_ending(operator: Operator, say: Say) -> int:
    ending = operator.ending or Ending.FAULT
    rig = operator.rig
    if ending is Ending.ESTOP:
        confirmed = bool((rig.get("estop") or {}).get("confirmed"))
        say("e-stopped: torque off" + (" (read back)" if confirmed else " (NOT read back)"))
        return ending.exit_code
    if operator.why:
        say(operator.why)
    fault = rig.get("fault")
    say(f"closed; fault: {fault['message'] if fault else 'none'}")
    return ending.exit_code
