"""One rig on a stage: what ``riderlive serve --nats URL --stage S --rig R`` runs in the web process.

- **Out**: every tick record on ``...<rig>.frame`` (rider + horse + the saddle pose, and the
  saddle estimate while a saddle input drives; RLF1 binary or JSON:
  the service's own codec), the status on ``...<rig>.status`` at once on change and every
  ``nats.status_interval`` s. The tick's callback only queues records (latest 0.25 s,
  older ones counted ``frames_dropped``); a task publishes them, so a slow or dead
  broker never delays the tick, the websockets or the takes. A tick that never reached
  the web process (lapped in the output ring) is counted ``frames_skipped``: every
  tick is ``frames_out``, ``frames_dropped``, ``frames_skipped`` or still queued.
- **In**: horse and saddle input and control (:mod:`riderlive.bus.inbound`); the stage e-stop,
  which latches the e-stop exactly as ``POST /api/estop`` does (source ``nats``); the
  stage heartbeat; discovery requests of ``riderlive stage``.
- **Stage dead-man** (:mod:`riderlive.bus.stage_deadman`, a task of its own with no broker
  I/O): without a stage heartbeat for ``nats.heartbeat_timeout`` s, an armed rig is
  disarmed (ease to park, then torque off), and arming is refused until the heartbeat is
  back. Nothing re-arms when it returns. A broker that dies, a cut cable, a stopped
  heartbeat source: all look the same, and all stop the stage rather than freezing it mid-move.
- **Names**: a rig name already answering on the stage is refused at start
  (:class:`RigNameTaken`); two rigs that raced to the same name see each other's status
  and count ``collisions`` (and say so in their status).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import os
import socket
import time
from collections import Counter, deque
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import orjson

from riderlive import prometheus
from riderlive.bus.config import NatsSection
from riderlive.bus.inbound import Control, InboundPort, ProducerInput, dumps
from riderlive.bus.stage_deadman import StageDeadMan
from riderlive.bus.subjects import Kind, Stage, parse
from riderlive.bus.transport import Message, NoResponders, Subscription, Transport, TransportError
from riderlive.channels import HORSE_NAMES
from riderlive.devices.latch import StopSource
from riderlive.devices.lifecycle import DeviceState
from riderlive.realtime import commands as cmd
from riderlive.realtime.record import RecordLayout
from riderlive.service.codecs import PROTOCOL_VERSION
from riderlive.service.rider_frames import encode_frame
from riderlive.timecode import TimecodeError

if TYPE_CHECKING:
    from collections.abc import Callable

    from riderlive.service.publish import Hub
    from riderlive.service.timecodes import ServiceTimecode


class RigPort(InboundPort, Protocol):
    """What a rig node uses of the service (``runtime.Service``): the inbound side's port,
    the hub's default subscription, and the lists it registers itself in while on stage."""

    @property
    def session(self) -> str: ...

    @property
    def hub(self) -> Hub: ...

    @property
    def timecode(self) -> ServiceTimecode: ...

    @property
    def sinks(self) -> list[Callable[[list[np.ndarray]], None]]:
        """Called with each batch of tick records."""
        ...


log = logging.getLogger(__name__)
QUEUE_SECONDS = 0.25
"""Records waiting for the broker beyond this age are dropped (as ``hub.CATCH_UP``)."""
NAME_CHECK_TIMEOUT = 0.5
STATUS_INTERVAL_MIN = 0.05
"""Seconds between looks for a changed tick status (producer sweeps ride along)."""
STATUS_PUBLISH_TIMEOUT = 1.0
"""A status publish waiting longer (a broker that does not take it) is dropped and counted."""


class RigNameTaken(TransportError):
    """Another rig answers on this stage under this name."""


def armed(status: dict[str, Any]) -> bool:
    """Some device is armed (homing, soft start, running) in a tick status."""
    for device in status.get("devices", []):
        with contextlib.suppress(ValueError):
            if DeviceState(device.get("state")).armed:
                return True
    return False


async def check_name_free(transport: Transport, stage: Stage, rig: str, session: str = "") -> None:
    """RigNameTaken when a rig already answers as ``rig`` on ``stage``."""
    subject = stage.rig(rig).subject(Kind.CONTROL)
    try:
        answer = await transport.request(subject, dumps({"action": "state"}), NAME_CHECK_TIMEOUT)
    except NoResponders:
        return
    except TimeoutError:
        raise RigNameTaken(f"rig name {rig!r} is in use on stage {stage.name!r} (it does not answer)") from None
    try:
        other = orjson.loads(answer)
    except orjson.JSONDecodeError:
        other = {}
    if other.get("session") == session and session:
        return
    where = f"{other.get('host', '?')} pid {other.get('pid', '?')}"
    raise RigNameTaken(f"rig name {rig!r} is already in use on stage {stage.name!r} (by {where}); choose another --rig")


class RigNode:
    """See the module docstring. ``start`` joins the stage, ``stop`` leaves it."""

    def __init__(self, service: RigPort, transport: Transport, config: NatsSection) -> None:
        assert config.rig is not None
        self.service = service
        self.transport = transport
        self.config = config
        self.stage = Stage(config.stage)
        self.subjects = self.stage.rig(config.rig)
        self.frame_subject = self.subjects.subject(Kind.FRAME)
        self.status_subject = self.subjects.subject(Kind.STATUS)
        trust = config.control_auth == "credentials"
        self.counts: Counter[str] = Counter()
        self.inputs = ProducerInput(service, transport, trust, config.producer_forget)
        self.dead_man = StageDeadMan(
            config.heartbeat_timeout,
            self.stage.name,
            armed=lambda: armed(service.link.status()),
            disarm=self._disarm_all,
            estop=lambda: service.supervisor.estop(StopSource.NATS),
            counts=self.counts,
        )
        self.control = Control(service, transport, trust, self.dead_man.arm_refusal, self.describe)
        self.subscription = dataclasses.replace(
            service.hub.default, horse=tuple(range(len(HORSE_NAMES))), encoding=config.encoding, saddle=True
        )
        self.queue: deque[np.ndarray] = deque()
        self.wake = asyncio.Event()
        self.first_seq: int | None = None
        """The first tick offered (since the tick last restarted)."""
        self.last_seq: int | None = None
        """The last tick offered (a restarted tick's seq starts again: counted from there)."""
        self._subs: list[Subscription] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._rates: dict[str, float] = {}
        self._last_counts: tuple[float, int, int, int, int] = (time.perf_counter(), 0, 0, 0, 0)

    # -- joining and leaving ----------------------------------------------------------------

    async def start(self) -> None:
        await check_name_free(self.transport, self.stage, self.subjects.rig, self.service.session)
        t = self.transport
        stage = self.stage
        self._subs = [
            await t.subscribe(self.subjects.subject(Kind.CONTROL, "*"), self.control.on_message, 256),
            await t.subscribe(self.subjects.horse_any(), self.inputs.on_message, 8192),
            await t.subscribe(self.subjects.saddle_any(), self.inputs.on_message, 8192),
            await t.subscribe(stage.subject(Kind.ESTOP, "*"), self.on_estop, 1024),
            await t.subscribe(stage.subject(Kind.HEARTBEAT, "*"), self.on_heartbeat, 1024),
            await t.subscribe(stage.subject(Kind.DISCOVER), self.on_discover, 256),
            await t.subscribe(self.status_subject, self.on_status, 256),
        ]
        await t.flush()
        self.service.arm_checks.append(self.dead_man.arm_refusal)
        self.service.sinks.append(self.offer)
        loop = asyncio.get_running_loop()
        self._tasks = [
            loop.create_task(self.dead_man.run()),
            loop.create_task(self._publisher()),
            loop.create_task(self._status()),
        ]
        log.warning("joined stage %r as rig %r", stage.name, self.subjects.rig)

    async def stop(self) -> None:
        with contextlib.suppress(ValueError):
            self.service.sinks.remove(self.offer)
        with contextlib.suppress(ValueError):
            self.service.arm_checks.remove(self.dead_man.arm_refusal)
        for task in self._tasks:
            task.cancel()
        for sub in self._subs:
            with contextlib.suppress(Exception):
                await sub.unsubscribe()
        self.inputs.close()
        with contextlib.suppress(Exception):
            await self.transport.publish(self.status_subject, dumps({**self.describe(), "leaving": True}))
            await self.transport.flush(1.0)
        await self.transport.close()

    # -- out --------------------------------------------------------------------------------

    def offer(self, records: list[np.ndarray]) -> None:
        """The tick's callback: queue the new records (never waits)."""
        if records:
            first, last = RecordLayout.seq.count(records[0]), RecordLayout.seq.count(records[-1])
            if self.last_seq is not None and first > self.last_seq + 1:
                self.counts["frames_skipped"] += first - self.last_seq - 1
            elif self.last_seq is None or first <= self.last_seq:
                self.first_seq = first
            self.counts["frames_skipped"] += max(0, last - first + 1 - len(records))  # a gap inside
            self.last_seq = last
        self.queue.extend(records)
        if self.queue:
            oldest = RecordLayout.engine_t.at(self.queue[-1]) - QUEUE_SECONDS
            while RecordLayout.engine_t.at(self.queue[0]) < oldest:
                self.queue.popleft()
                self.counts["frames_dropped"] += 1
        self.wake.set()

    async def _publisher(self) -> None:
        while True:
            await self.wake.wait()
            self.wake.clear()
            while self.queue:
                record = self.queue.popleft()
                data = encode_frame(self.subscription, record)
                await self.transport.publish(self.frame_subject, data if isinstance(data, bytes) else data.encode())
                self.counts["frames_out"] += 1

    def describe(self) -> dict[str, Any]:
        """This rig's status message (``...<rig>.status``, discovery, ``state``)."""
        service = self.service
        status = service.link.status()
        now = time.perf_counter()
        beat = self.dead_man.last_heartbeat
        age = None if beat is None else now - beat
        devices = [{"name": d.get("name"), "state": d.get("state")} for d in status.get("devices", [])]
        return {
            "type": "status",
            "protocol": PROTOCOL_VERSION,
            "stage": self.stage.name,
            "rig": self.subjects.rig,
            "session": service.session,
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "tick_up": service.supervisor.up,
            "tick_rate": service.config.tick.rate,
            "driver": status.get("driver"),
            "estop": service.link.latch.latched,
            "devices": devices,
            "rates": dict(self._rates),
            "heartbeat": {"timeout": self.config.heartbeat_timeout, "age": age, "ok": not self.dead_man.lost},
            "perf_origin": service.link.start,
            "channels": list(service.hub.names),
            "counts": dict(self.counts),
            "frames": {"first_seq": self.first_seq, "last_seq": self.last_seq, "queued": len(self.queue)},
            "output_lapped": int(service.link.outputs.lapped),  # records read too late: never published
            "transport": dict(self.transport.stats.events),
        }

    def _update_rates(self, now: float) -> None:
        then, ticks, out, horse_in, saddle_in = self._last_counts
        metrics = self.service.metrics
        horse_now, saddle_now = self.inputs.accepted(Kind.HORSE), self.inputs.accepted(Kind.SADDLE)
        dt = max(now - then, 1e-6)
        self._rates = {
            "ticks_hz": (metrics.ticks_published - ticks) / dt,
            "frames_out_hz": (self.counts["frames_out"] - out) / dt,
            "horse_in_hz": (horse_now - horse_in) / dt,
            "saddle_in_hz": (saddle_now - saddle_in) / dt,
        }
        self._last_counts = (now, metrics.ticks_published, self.counts["frames_out"], horse_now, saddle_now)

    # -- in ---------------------------------------------------------------------------------

    async def on_estop(self, msg: Message) -> None:
        """The stage e-stop: latched at once, whatever the payload or version (counted)."""
        latched = self.service.supervisor.estop(StopSource.NATS)
        self.counts["estops"] += 1
        parsed = parse(msg.subject)
        if parsed is None or not parsed.known_version:
            self.service.metrics.bad_frames["unknown_version"] += 1
        if msg.reply:
            await self.transport.publish(msg.reply, dumps({"rig": self.subjects.rig, "latched_at": latched}))

    async def on_heartbeat(self, msg: Message) -> None:
        parsed = parse(msg.subject)
        if parsed is None or not parsed.known_version:
            self.service.metrics.bad_frames["unknown_version"] += 1
            return
        self.dead_man.beat()
        self.counts["heartbeats"] += 1
        self.stage_timecode(msg.data)

    def stage_timecode(self, data: bytes) -> None:
        """A heartbeat's ``tc``: the stage-wide timecode reference; unusable: counted (timecode errors)."""
        try:
            body = orjson.loads(data)
        except orjson.JSONDecodeError:
            return
        if isinstance(body, dict) and "tc" in body:
            with contextlib.suppress(TimecodeError):  # counted by ServiceTimecode
                self.service.timecode.stage_beat(self.service.link.engine_time(), body["tc"], body.get("tc_rate"))

    async def on_discover(self, msg: Message) -> None:
        if msg.reply:
            await self.transport.publish(msg.reply, dumps(self.describe()))

    async def on_status(self, msg: Message) -> None:
        """Our own status subject: another session publishing on it is a name collision."""
        try:
            session = orjson.loads(msg.data).get("session")
        except (orjson.JSONDecodeError, AttributeError):
            session = None
        if session != self.service.session:
            self.counts["collisions"] += 1
            if self.counts["collisions"] == 1:
                log.critical("another rig publishes as %r on stage %r: rename one", self.subjects.rig, self.stage.name)

    # -- the stage dead-man's disarm, the status ---------------------------------------------

    async def _disarm_all(self, by: str) -> str | None:
        reply = await self.service.supervisor.ask(lambda r: cmd.Disarm(None, by, r))
        return None if reply.ok else reply.message

    async def _status(self) -> None:
        """Producer sweeps; the status on change and every ``status_interval`` s. A publish
        that waits longer than ``STATUS_PUBLISH_TIMEOUT`` is dropped and counted, and a pass
        that raises is logged and counted: the loop goes on (the dead-man is not in it)."""
        next_status = 0.0
        status_version = -1
        while True:
            await asyncio.sleep(STATUS_INTERVAL_MIN)
            now = time.perf_counter()
            try:
                self.inputs.sweep(now)
                version = self.service.link.status_blob.version
                if now >= next_status or version != status_version:
                    if now >= next_status:
                        self._update_rates(now)
                        next_status = now + self.config.status_interval
                    status_version = version
                    status = dumps(self.describe())
                    publish = self.transport.publish(self.status_subject, status)
                    try:
                        await asyncio.wait_for(publish, STATUS_PUBLISH_TIMEOUT)
                    except TimeoutError:
                        self.counts["status_timeouts"] += 1
            except Exception:
                self.counts["status_errors"] += 1
                log.exception("the rig status pass failed (counted; it goes on)")


async def join_stage(service: RigPort) -> RigNode:
    """Connect to the broker of ``service.config.nats`` and join its stage as a rig."""
    from riderlive.bus.nats import connect, credentials_of

    config = service.config.nats
    assert config.url is not None
    transport = await connect(
        config.url, credentials_of(config), f"riderlive rig {config.rig}", connect_timeout=config.connect_timeout
    )
    node = RigNode(service, transport, config)
    try:
        await node.start()
    except BaseException:
        await transport.close()
        raise
    return node


def render_metrics(node: RigNode) -> str:
    """Prometheus text for the stage link."""
    out = prometheus.Exposition()
    out.one(
        "riderlive_nats_connected",
        prometheus.Kind.GAUGE,
        "1 while connected to the stage's broker.",
        node.transport.connected,
    )
    events = Counter(node.counts) + Counter(node.transport.stats.events)
    help_text = "Stage link events (frames, heartbeats, stops, broker events)."
    out.by_label("riderlive_nats_events_total", prometheus.Kind.COUNTER, help_text, "event", sorted(events.items()))
    return out.text()
