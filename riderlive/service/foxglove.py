"""``riderlive serve --foxglove PORT``: the Foxglove WebSocket protocol (``foxglove.websocket.v1``)
with the official SDK (PyPI ``foxglove-sdk``), fed from the same tick records as ``/ws/rider``.

The SDK's server runs in its own (Rust) threads inside the web process; :meth:`FoxgloveLive.publish`
is a sink of the service (:class:`~riderlive.service.ports.PublishPort`) (called on the event loop with each
batch of new records) and only hands bytes to the SDK, which queues them per client and never
blocks the caller. Topics and schemas are :mod:`riderlive.export.foxglove`'s (the same as
``export --format mcap``): the joints at every tick, ``/tf`` at ``foxglove.tf_rate``, ``/status``
when it changes. Nothing is encoded for a topic no client subscribes to.

Bad clients (docs/foxglove.md): a subscription to a channel that does not exist is answered by
the SDK with a status error; a client that stops reading has its queue
(``foxglove.backlog`` messages) fill, then the SDK drops that client's messages (and, past its
own limits, the client) without slowing anyone else: the joints each client was sent and the
subscriptions are counted here (``riderlive_foxglove_*``), the SDK logs its drops.
"""

from __future__ import annotations

import logging
import sys
import time
from collections import Counter
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson
from foxglove.websocket import ServerListener

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.export import foxglove as fx
from riderlive.realtime.record import RecordLayout

if TYPE_CHECKING:
    import foxglove

    from riderlive.service.ports import PublishPort

log = logging.getLogger(__name__)


class _Listener(ServerListener):
    """The SDK's server listener: counts subscriptions."""

    def __init__(self, counts: Counter[str]) -> None:
        self.counts = counts

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.counts["subscribe"] += 1

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self.counts["unsubscribe"] += 1


class FoxgloveLive:
    """One SDK server and its channels, on one service."""

    def __init__(self, service: PublishPort, host: str, port: int, tf_rate: float, backlog: int) -> None:
        import foxglove

        self.service = service
        self.counts: Counter[str] = Counter()
        self.context = foxglove.Context()
        self.server = foxglove.start_server(
            name="riderlive",
            host=host,
            port=port,
            context=self.context,
            server_listener=_Listener(self.counts),
            message_backlog_size=backlog,
        )
        self.port = self.server.port
        rider_names = RIDER_NAMES
        topics = fx.schemas(rider_names, HORSE_NAMES).topics
        self.channels: dict[str, foxglove.Channel] = {}
        for topic, (name, encoding, data, message_encoding) in topics.items():
            schema = foxglove.Schema(name=name, encoding=encoding, data=data)
            self.channels[topic] = foxglove.Channel(
                topic, schema=schema, message_encoding=message_encoding, context=self.context
            )
        self.frames = fx.skeleton_frames(*_rigs())
        self.rider_joints, self.horse_joints = fx.JointsEncoder(RIDER_NAMES), fx.JointsEncoder(HORSE_NAMES)
        self.tf_every = max(1, round(service.config.tick.rate / tf_rate))
        self._status_version = -1
        print(
            f"riderlive serve: Foxglove WebSocket on port {self.port} (ws://{host}:{self.port})",
            file=sys.stderr,
            flush=True,
        )

    def publish(self, records: list[np.ndarray]) -> None:
        """New tick records (oldest first) to the subscribed topics; never blocks."""
        rider, horse, tf = (self.channels[t] for t in (fx.RIDER_TOPIC, fx.HORSE_TOPIC, fx.TF_TOPIC))
        want_rider, want_horse, want_tf = rider.has_sinks(), horse.has_sinks(), tf.has_sinks()
        wall = self.service.timecode.wall_ns
        if want_rider or want_horse or want_tf:
            stamps = self.service.timecode
            for record in records:
                engine_t, seq = RecordLayout.engine_t.at(record), RecordLayout.seq.count(record)
                time_ns = wall(engine_t)
                label = stamps.of_record(record).label if (want_rider or want_horse) else ""
                if want_rider:
                    values = record[RecordLayout.rider.slice]
                    rider.log(self.rider_joints.encode(seq, engine_t, label, values), log_time=time_ns)
                    self.counts["rider_messages"] += 1
                if want_horse:
                    values = record[RecordLayout.horse.slice]
                    horse.log(self.horse_joints.encode(seq, engine_t, label, values), log_time=time_ns)
                if want_tf and seq % self.tf_every == 0:
                    tf.log(fx.frame_transforms(time_ns, self.frames, self._poses(record)), log_time=time_ns)
        self._status()

    def _poses(self, record: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        poses = self.service.poses
        out = []
        for pose in (poses.horse(record), poses.rider(record)):
            out.append((np.asarray(pose.local_offsets), np.asarray(pose.local_rotations)))
        return out

    def _status(self) -> None:
        link = self.service.link
        version = link.status_blob.version
        channel = self.channels[fx.STATUS_TOPIC]
        if version != self._status_version and channel.has_sinks():
            self._status_version = version
            channel.log(orjson.dumps(link.status(), option=orjson.OPT_SERIALIZE_NUMPY), log_time=time.time_ns())

    def status(self) -> dict[str, Any]:
        return {"port": self.port, "tf_every": self.tf_every, **self.counts}

    def stop(self) -> None:
        self.server.stop()


def _rigs() -> tuple[Any, Any]:
    from riderlive.skeleton import HORSE_RIG, rider_rig

    return HORSE_RIG, rider_rig()
