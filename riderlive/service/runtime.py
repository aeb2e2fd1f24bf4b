"""The running service inside the web process: tick link, fan-out, sources, takes."""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from riderlive.channels import HORSE_NAMES
from riderlive.realtime import commands as cmd
from riderlive.realtime import layout as L
from riderlive.realtime.core import Mode, Timing
from riderlive.realtime.link import TickLink
from riderlive.realtime.tick import TickSetup
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.params import RuleParams, load_preset
from riderlive.service.config import ServiceConfig
from riderlive.service.ingest import Arbiter, IngestEndpoint, Producer, next_producer_id
from riderlive.service.metrics import ServiceMetrics
from riderlive.service.poses import RecordPoses
from riderlive.service.publish import Hub
from riderlive.takes.recorder import TakeRecorder, take_path
from riderlive.takes.replay import Replay, load_replay

log = logging.getLogger(__name__)


def make_setup(config: ServiceConfig, params: RuleParams, extra_channels: tuple[str, ...] = ()) -> TickSetup:
    source = config.source
    timing = Timing(
        delay=config.input.delay,
        hold=config.input.hold,
        ease_time=config.input.ease_time,
        blend_time=config.input.blend_time,
        resume_after=source.resume_after,
        fallback_procedural=source.fallback_procedural,
    )
    return TickSetup(
        rate=config.tick.rate,
        start=time.perf_counter(),
        timing=timing,
        params=params,
        animator=AnimatorLayer(),
        length_scale=config.tick.length_scale,
        gait=source.gait,
        speed=source.speed,
        seed=source.seed,
        mode=Mode.PROCEDURAL if source.kind == "procedural" else Mode.INPUT,
        realtime_priority=config.tick.realtime_priority,
        isolation=config.tick.isolation,
        spin=config.tick.spin,
        rig_file=config.rig.file,
        rig_port=config.rig.port,
        park_timeout=config.rig.park_timeout,
        tail=config.physics.tail,
        physics_file=config.physics.file,
        extra_channels=extra_channels,
    )


class Service:
    """Everything ``riderlive serve`` runs in the web process, started by the app's lifespan."""

    def __init__(self, config: ServiceConfig) -> None:
        self.config = config
        self.session = uuid.uuid4().hex
        self.extra_channels: tuple[str, ...] = ()
        """Channels published after the rider's: the tail and braid when ``physics.tail``."""
        if config.physics.tail:
            from riderlive.realtime.tail import physics_channels  # numba: imported only when on

            self.extra_channels = physics_channels(config.physics.file)
        self.params = load_preset(config.tick.preset)
        self.animator = AnimatorLayer()
        self.metrics = ServiceMetrics()
        self.poses = RecordPoses(config.tick.length_scale)
        """Skeleton poses of tick records, solved once for /ws/rider and VMC."""
        self.vmc = None
        if config.vmc.target is not None:
            from riderlive.vmc.sender import VmcSender  # raises VmcError: a host that does not resolve, a port in use

            self.vmc = VmcSender.open(self.poses, config.vmc, config.tick.rate, self.metrics.vmc)
        self.arbiter = Arbiter(config.input.producer_timeout)
        self.hub = Hub(self)
        self.ingest = IngestEndpoint(self)
        self.source: dict[str, Any] = {"kind": config.source.kind}
        if config.source.kind == "procedural":
            self.source.update(gait=config.source.gait, speed=config.source.speed)
            self.arbiter.selection = "procedural"
        self.recorder: TakeRecorder | None = None
        self.take_name: str | None = None
        self._replay_task: asyncio.Task[None] | None = None
        self._status_version = -1
        self.link: TickLink

    # -- lifecycle ------------------------------------------------------------
    async def start(self) -> None:
        self.link = TickLink(make_setup(self.config, self.params, self.extra_channels))
        loop = asyncio.get_running_loop()
        loop.add_reader(self.link.notify_fd, self.on_tick)
        self._watchdog = loop.create_task(self._watch_tick())

    async def _watch_tick(self) -> None:
        """Say so loudly if the tick process dies: no frames, no rig (its servos' watchdog stops them)."""
        while self.link.alive():
            await asyncio.sleep(0.5)
        log.critical("the tick process has died: no rider frames until the service restarts")
        self.hub.publish_status({**self.link.status(), "driver": "dead", "tick_alive": False})

    async def stop(self) -> None:
        """Goodbye to clients, park the rig and stop the tick, close the take."""
        await self.hub.goodbye("shutdown")
        self._watchdog.cancel()
        if self._replay_task is not None:
            self._replay_task.cancel()
        asyncio.get_running_loop().remove_reader(self.link.notify_fd)
        await asyncio.to_thread(self.link.stop, self.config.rig.park_timeout + 2.0)
        self.on_tick()
        self.stop_recording()
        self.link.close()
        if self.vmc is not None:
            self.vmc.close()

    # -- the tick's records ---------------------------------------------------
    def on_tick(self) -> None:
        """Notify pipe readable: record every new tick, publish the newest."""
        link = self.link
        link.drain_notify()
        records = link.read_outputs()
        if self.recorder is not None:
            for record in records:
                self.recorder.add(
                    float(record[L.OUT_ENGINE_T]), record[L.OUT_HORSE : L.OUT_RIDER], record[L.OUT_RIDER :]
                )
        if records:
            self.metrics.ticks_coalesced += len(records) - 1
            self.metrics.ticks_published += 1
            self.hub.publish(records)
            if self.vmc is not None:
                self.vmc.publish(records)
        version = link.status_blob.version
        if version != self._status_version:
            self._status_version = version
            self.hub.publish_status(link.status())

    # -- sources --------------------------------------------------------------
    async def set_source(self, request: dict[str, Any]) -> dict[str, Any]:
        kind = request["kind"]
        self._cancel_replay()
        if kind == "procedural":
            gait, speed = request.get("gait"), request.get("speed")
            if gait is not None:
                self.link.send(cmd.SetGait(gait, speed))
            self.arbiter.selection = "procedural"
            self.link.send(cmd.SetMode(Mode.PROCEDURAL))
            self.source = {"kind": "procedural", "gait": gait, "speed": speed}
        elif kind == "live":
            self.arbiter.selection = "live"
            self.link.send(cmd.SetMode(Mode.INPUT))
            self.source = {"kind": "live"}
        else:
            path = take_path(self.config.takes.directory, request["take"])
            replay = await asyncio.to_thread(load_replay, path, self.config.tick.rate)
            producer = Producer(id=next_producer_id(), name=f"replay:{replay.name}")
            self.arbiter.replay_id = producer.id
            self.arbiter.selection = "replay"
            self.link.send(cmd.SetMode(Mode.INPUT))
            self.source = {"kind": "replay", "take": replay.name, "loop": bool(request.get("loop", False))}
            self._replay_task = asyncio.get_running_loop().create_task(
                self._play(replay, producer, bool(request.get("loop", False)))
            )
        return self.source

    def _cancel_replay(self) -> None:
        if self._replay_task is not None:
            self._replay_task.cancel()
            self._replay_task = None
        if self.arbiter.replay_id is not None:
            self.link.send(cmd.ProducerGone(self.arbiter.replay_id))
            self.arbiter.replay_id = None

    async def _play(self, replay: Replay, producer: Producer, loop: bool) -> None:
        """Feed a take's horse frames to the tick at their original timing."""
        link = self.link
        period = float(replay.t[1] - replay.t[0]) if len(replay.t) > 1 else 1.0 / self.config.tick.rate
        t_shift = 0.0
        base = link.engine_time()
        while True:
            for t, frame in zip(replay.t, replay.horse, strict=True):
                due = base + (t - replay.t[0])
                delay = due - link.engine_time()
                if delay > 0.0:
                    await asyncio.sleep(delay)
                link.push_input(producer.id, float(t) + t_shift, link.engine_time(), frame)
                self.metrics.frames_in[producer.name] += 1
            if not loop:
                break
            t_shift += replay.duration + period
            base += replay.duration + period
        # The take ended: its stream goes stale, the rider eases, live may drive again.
        link.send(cmd.ProducerGone(producer.id))
        self.arbiter.replay_id = None
        self.arbiter.selection = "live"
        self.source = {"kind": "live", "after": f"replay:{replay.name}"}

    # -- rules ----------------------------------------------------------------
    def set_model(self, params: RuleParams | None = None, animator: AnimatorLayer | None = None) -> None:
        self.params = params or self.params
        self.animator = animator or self.animator
        self.link.send(cmd.SetModel(self.params, self.animator))

    # -- takes ----------------------------------------------------------------
    def start_recording(self, name: str | None) -> str:
        self.stop_recording()
        name = name or datetime.now(UTC).strftime("take-%Y%m%d-%H%M%S")
        path = take_path(self.config.takes.directory, name)
        meta = {
            "session": self.session,
            "tick_rate": self.config.tick.rate,
            "preset": self.params.name,
            "length_scale": self.config.tick.length_scale,
        }
        self.recorder = TakeRecorder(path, self.config.takes.flush_interval, meta, self.extra_channels)
        self.take_name = path.stem
        return path.stem

    def stop_recording(self) -> dict[str, Any] | None:
        if self.recorder is None:
            return None
        recorder, self.recorder = self.recorder, None
        recorder.close()
        return {"name": recorder.path.stem, "rows": recorder.rows, "path": str(Path(recorder.path))}

    def state(self) -> dict[str, Any]:
        link = self.link
        return {
            "session": self.session,
            "engine_time": link.engine_time(),
            "tick_alive": link.alive(),
            "tick": link.status(),
            "counters": link.counters.snapshot(),
            "source": self.source,
            "arbitration": {
                "selection": self.arbiter.selection,
                "active": self.arbiter.active,
                "producers": [
                    {"id": p.id, "name": p.name, "priority": p.priority, "accepted": p.accepted, "rejected": p.rejected}
                    for p in self.arbiter.producers.values()
                ],
            },
            "clients": [{"id": c, "sent": s, "dropped": d} for c, _, s, d in self.hub.snapshot()],
            "recording": None if self.recorder is None else {"name": self.take_name, "rows": self.recorder.rows},
            "preset": self.params.name,
            "horse_channels": list(HORSE_NAMES),
            "vmc": None if self.vmc is None else self.vmc.status(),
        }
