"""The running service inside the web process: tick link, fan-out, sources, takes."""

from __future__ import annotations

import asyncio
import logging
import math
import time
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, RIDER_PART_NAMES, SADDLE_NAMES
from riderlive.horse import TerrainConfig
from riderlive.realtime import commands as cmd
from riderlive.realtime.core import Mode
from riderlive.realtime.latency import LatencySnapshot
from riderlive.realtime.link import TickLink
from riderlive.realtime.record import RecordLayout
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams, load_preset
from riderlive.service.arbiter import SADDLE_INPUT, Arbiter, Producer, next_producer_id
from riderlive.service.config import ServiceConfig
from riderlive.service.devices_api import DeviceMetrics, plan_devices
from riderlive.service.ingest import IngestEndpoint
from riderlive.service.kworkers import KernelWorkers, host_status, keep_raised
from riderlive.service.metrics import ServiceMetrics
from riderlive.service.poses import RecordPoses
from riderlive.service.publish import Hub
from riderlive.service.supervisor import TickSupervisor
from riderlive.service.tick_setup import make_setup
from riderlive.service.timecodes import host_timecode
from riderlive.takes.recorder import TakeExists, TakeRecorder, read_sidecar, recover_take, replay_path, take_path
from riderlive.takes.replay import Replay, load_replay
from riderlive.takes.stamp import start_index, take_timecode

if TYPE_CHECKING:
    from riderlive.bus.rig import RigNode
    from riderlive.service.foxglove import FoxgloveLive

log = logging.getLogger(__name__)


class Service:
    """Everything ``riderlive serve`` runs in the web process, started by the app's lifespan."""

    def __init__(self, config: ServiceConfig) -> None:
        self.config = config
        self.session = uuid.uuid4().hex
        self.physics_channels: tuple[str, ...] = ()
        """The tail and braid when ``physics.tail`` (recorded in takes)."""
        if config.physics.tail:
            from riderlive.realtime.tail import physics_channels  # numba: imported only when on

            self.physics_channels = physics_channels(config.physics.file)
        self.layout = RecordLayout(self.physics_channels, RIDER_PART_NAMES)
        """The tick's output record (``realtime/record.py``): after the rider, the tail and braid, then the parts."""
        self.extra_channels = self.layout.extra_channels
        self.devices = plan_devices(config)
        """The devices the tick drives (validated, rates fitted; the wire budget was printed)."""
        self.params: RuleParams
        self.animator: AnimatorLayer
        """Both set by ``_report_configured`` below, with the source."""
        self.metrics = ServiceMetrics()
        self.timecode = host_timecode(config.timecode, time.perf_counter(), self.metrics.timecode)
        """Each record's SMPTE timecode (producer, stage or host clock); re-anchored on the tick link at start."""
        self.poses = RecordPoses(config.tick.length_scale)
        """Skeleton poses of tick records, solved once for /ws/rider and VMC."""
        self.vmc = None
        if config.vmc.target is not None:
            # raises VmcError: a host that does not resolve, a port in use
            from riderlive.service.vmc_out import VmcSender

            self.vmc = VmcSender.open(self.poses, config.vmc, config.tick.rate, self.metrics.vmc)
            self.vmc.timecode = lambda record: self.timecode.of_record(record).label
        self.arbiter = Arbiter(config.input.producer_timeout)
        self.hub = Hub(self)
        self.ranges = config.ranges.ranges()
        self.ingest = IngestEndpoint(self, self.ranges)
        self.saddle_ingest = IngestEndpoint(self, self.ranges, SADDLE_INPUT)
        """``/ws/saddle``: the same endpoint on the saddle's channels, the same arbiter."""
        low, high = self.ranges.limits(HORSE_NAMES, config.tick.length_scale)
        mixed = [a if i % 2 else b for i, (a, b) in enumerate(zip(low, high, strict=True))]
        self._probes = [[0.0] * len(low), low, high, mixed]
        """Horse frames ``set_model`` checks new parameters on: neutral and corners of the ranges."""
        self.source: dict[str, Any] = {}
        self._report_configured()
        self.recorder: TakeRecorder | None = None
        self.take_name: str | None = None
        self._replay_task: asyncio.Task[None] | None = None
        self._status_version = -1
        self.link: TickLink
        self.supervisor: TickSupervisor
        self.device_metrics: DeviceMetrics
        self.sinks: list[Callable[[list[np.ndarray]], None]] = []
        """More consumers of the tick's records (the stage link); called on the event loop, never waiting."""
        self.arm_checks: list[Callable[[], str | None]] = []
        """Each says why arming must wait (e.g. no stage heartbeat), or None."""
        self.stage: RigNode | None = None
        self.foxglove: FoxgloveLive | None = None
        priority = config.host.kernel_workers_priority
        self.host_workers = KernelWorkers(priority) if priority else None
        """The kernel's unbound workers kept at SCHED_FIFO ``host.kernel_workers_priority`` (service/kworkers.py)."""
        self._workers_task: asyncio.Task[None] | None = None

    def _report_configured(self) -> None:
        """Preset, animator layer and source as configured (at start, and when a restarted
        tick falls back to the configured settings)."""
        config = self.config
        self.params = load_preset(config.tick.preset)
        self.animator = AnimatorLayer()
        self.source = {"kind": config.source.kind}
        self.arbiter.selection = "live"
        if config.source.kind == "procedural":
            self.source.update(gait=config.source.gait, speed=config.source.speed)
            self.arbiter.selection = "procedural"

    def _tick_fell_back(self) -> None:
        """The supervisor restarts the tick with the configured settings: report those."""
        self._cancel_replay()
        self._report_configured()

    # -- lifecycle ------------------------------------------------------------
    async def start(self) -> None:
        self.recover_takes()
        self.link = TickLink(make_setup(self.config, self.params, self.layout, self.devices))
        self.timecode = host_timecode(self.config.timecode, self.link.start, self.metrics.timecode)
        self.supervisor = TickSupervisor(
            self.link, self.config, self.on_tick, self.hub.publish_status, self._tick_fell_back
        )
        if self.host_workers is not None:  # here, not in the tick: it survives a tick's death
            self._workers_task = asyncio.create_task(keep_raised(self.host_workers))
        await self.supervisor.start()
        section = self.config.foxglove
        if section.port is not None:
            from riderlive.service.foxglove import FoxgloveLive

            self.foxglove = FoxgloveLive(self, self.config.server.host, section.port, section.tf_rate, section.backlog)
            self.sinks.append(self.foxglove.publish)
        if self.config.nats.url is not None:
            from riderlive.bus.rig import join_stage

            self.stage = await join_stage(self)

    async def stop(self) -> None:
        """Goodbye to clients, park the devices and stop the tick, the guardian, the take."""
        await self.hub.goodbye("shutdown")
        if self.stage is not None:
            await self.stage.stop()
        await self.supervisor.stop()
        if self._replay_task is not None:
            self._replay_task.cancel()
        await asyncio.to_thread(self.link.stop, self.config.rig.park_timeout + 2.0)
        await asyncio.to_thread(self.supervisor.stop_guardian)
        self.on_tick()
        self.stop_recording()
        self.link.close()
        if self.vmc is not None:
            self.vmc.close()
        if self.foxglove is not None:
            self.foxglove.stop()
        if self._workers_task is not None:  # after the devices are parked: restores the workers
            self._workers_task.cancel()
            await asyncio.gather(self._workers_task, return_exceptions=True)

    # -- the tick's records ---------------------------------------------------
    def on_tick(self) -> None:
        """Notify pipe readable: record every new tick, publish the newest."""
        link = self.link
        link.drain_notify()
        records = link.read_outputs()
        if self.recorder is not None:
            start = link.start
            recorded = slice(
                RecordLayout.rider.start, self.layout.physics.stop
            )  # the rider and the physics, not the parts
            for record in records:
                engine_t = RecordLayout.engine_t.at(record)
                if self.recorder.rows == 0:  # the take's start timecode, in its sidecar from the first flush
                    self.recorder.meta.update(self.timecode.of_record(record).as_meta())
                rider = np.concatenate((record[recorded], record[RecordLayout.saddle.slice]))  # then the saddle
                self.recorder.add(engine_t, record[RecordLayout.horse.slice], rider, engine_t + start)
        if records:
            self.metrics.ticks_published += len(records)
            self.hub.publish(records)
            if self.vmc is not None:
                self.vmc.publish(records)
            for sink in self.sinks:
                sink(records)
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
                self.link.apply(cmd.SetGait(gait, speed), gait=gait, speed=speed)  # None: the gait's own
            ground = None if request.get("terrain") is None else TerrainConfig.model_validate(request["terrain"])
            if ground is not None:  # live, from the horse's next tick; a restarted tick starts on it
                self.link.apply(cmd.SetTerrain(ground), terrain=ground)
            self.arbiter.selection = "procedural"
            self.link.apply(cmd.SetMode(Mode.PROCEDURAL), mode=Mode.PROCEDURAL)
            self.source = {"kind": "procedural", "gait": gait, "speed": speed}
            if ground is not None:
                self.source["terrain"] = ground.model_dump(exclude_none=True)
        elif kind == "live":
            self.arbiter.selection = "live"
            self.link.apply(cmd.SetMode(Mode.INPUT), mode=Mode.INPUT)
            self.source = {"kind": "live"}
        else:
            path = replay_path(self.config.takes.directory, request["take"])
            if not path.is_file():
                raise FileNotFoundError(path.name)
            if self.recorder is not None and self.recorder.path == path:
                raise TakeExists(f"take {path.stem!r} is being recorded; stop it first")
            limits = self.ranges.limits(HORSE_NAMES, self.config.tick.length_scale)
            await asyncio.to_thread(recover_take, path)
            length_scale = self.config.tick.length_scale
            replay = await asyncio.to_thread(load_replay, path, self.config.tick.rate, limits, length_scale)
            stamp = take_timecode(read_sidecar(path))  # TimecodeError (a ValueError): a broken sidecar
            first_t = float(replay.t[0])
            if request.get("from_tc") is not None:
                start = start_index(replay.t, stamp, request["from_tc"], replay.name)
                replay = Replay(replay.name, replay.t[start:], replay.horse[start:])
            producer = Producer(id=next_producer_id(), name=f"replay:{replay.name}")
            if stamp is not None:  # the replay's records carry the take's own labels
                self.timecode.streams[producer.id] = stamp.at_rate(self.timecode.rate).anchor(float(first_t))
            self.arbiter.replay_id = producer.id
            self.arbiter.selection = "replay"
            self.link.apply(cmd.SetMode(Mode.INPUT), mode=Mode.INPUT)
            self.source = {"kind": "replay", "take": replay.name, "loop": bool(request.get("loop", False))}
            if request.get("from_tc") is not None:
                self.source["from_tc"] = request["from_tc"]
            self._replay_task = asyncio.get_running_loop().create_task(
                self._play(replay, producer, bool(request.get("loop", False)))
            )
        return self.source

    def _cancel_replay(self) -> None:
        if self._replay_task is not None:
            self._replay_task.cancel()
            self._replay_task = None
        if self.arbiter.replay_id is not None:
            self.link.tell(cmd.ProducerGone(self.arbiter.replay_id))
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
                self.metrics.count_frame_in(producer.name)
            if not loop:
                break
            t_shift += replay.duration + period
            base += replay.duration + period
        # The take ended: its stream goes stale, the rider eases, live may drive again.
        link.tell(cmd.ProducerGone(producer.id))
        self.arbiter.replay_id = None
        self.arbiter.selection = "live"
        self.source = {"kind": "live", "after": f"replay:{replay.name}"}

    # -- rules ----------------------------------------------------------------
    def set_model(self, params: RuleParams | None = None, animator: AnimatorLayer | None = None) -> None:
        """Send new parameters or animator layer to the tick (it blends to them).

        ValueError, changing nothing, when they give a non-finite rider for a horse
        at the corners of its plausible ranges (the tick would have to hold its last frame).
        """
        params = params or self.params
        animator = animator or self.animator
        model = RiderModel(params=params, scale=self.config.tick.length_scale, animator=animator)
        for horse in self._probes:
            rider = model.evaluate(horse)
            bad = next((name for name, v in zip(RIDER_NAMES, rider, strict=True) if not math.isfinite(v)), None)
            if bad is not None:
                raise ValueError(f"these parameters make {bad} non-finite for a plausible horse; not applied")
        self.params, self.animator = params, animator
        self.link.apply(cmd.SetModel(params, animator), params=params, animator=animator)

    # -- takes ----------------------------------------------------------------
    def recover_takes(self) -> None:
        """Takes a kill interrupted (sidecar not ``complete``): trim a cut last line, mark them."""
        folder = Path(self.config.takes.directory)
        for path in sorted(folder.glob("*.csv")) if folder.is_dir() else ():
            try:
                if recover_take(path):
                    log.warning("take %s was interrupted (killed?): recovered", path.name)
            except OSError as exc:
                log.warning("take %s could not be recovered: %s", path.name, exc)

    def start_recording(self, name: str | None, overwrite: bool = False) -> str:
        """Start a take; the one being recorded is closed only once the new one is open.

        A bad name (ValueError) or an existing take without ``overwrite``
        (:class:`TakeExists`) changes nothing.
        """
        directory = self.config.takes.directory
        if name is None:
            stem = datetime.now(UTC).strftime("take-%Y%m%d-%H%M%S")
            path = take_path(directory, stem)
            n = 1
            while path.exists():
                n += 1
                path = take_path(directory, f"{stem}-{n}")
        else:
            path = take_path(directory, name)
        meta = {
            "session": self.session,
            "tick_rate": self.config.tick.rate,
            "preset": self.params.name,
            "length_scale": self.config.tick.length_scale,
        }
        extra = (*self.physics_channels, *SADDLE_NAMES)  # the saddle of every tick's horse, after the rider's
        recorder = TakeRecorder(path, self.config.takes.flush_interval, meta, extra, overwrite)
        self.stop_recording()
        self.recorder = recorder
        self.take_name = path.stem
        return path.stem

    def stop_recording(self) -> dict[str, Any] | None:
        if self.recorder is None:
            return None
        recorder, self.recorder = self.recorder, None
        recorder.close()
        return {"name": recorder.path.stem, "rows": recorder.rows, "path": str(Path(recorder.path))}

    def latency(self) -> dict[str, LatencySnapshot]:
        """Snapshots of ``tick_lateness``, ``ingest_to_wire`` (the tick's) and ``ingest_to_send``."""
        out = {name: histogram.snapshot() for name, histogram in self.link.histograms.items()}
        out["ingest_to_send"] = self.metrics.ingest_to_send.snapshot()
        return out

    def state(self) -> dict[str, Any]:
        link = self.link
        return {
            "session": self.session,
            "engine_time": link.engine_time(),
            "engine_epoch": link.start,
            "tick_alive": link.alive(),
            "supervision": self.supervisor.snapshot(),
            "tick": link.status(),
            "counters": link.counters.snapshot(),
            "source": self.source,
            "arbitration": self.arbiter.status(),
            "clients": self.hub.describe_clients(),
            "recording": None if self.recorder is None else {"name": self.take_name, "rows": self.recorder.rows},
            "preset": self.params.name,
            "horse_channels": list(HORSE_NAMES),
            "vmc": None if self.vmc is None else self.vmc.status(),
            "timecode": self.timecode.status(link.engine_time()),
            "foxglove": None if self.foxglove is None else self.foxglove.status(),
            "host": host_status(self.host_workers),
        }
