"""Follow a rig on a stage over NATS from Python (``pip install riderlive[nats]``; docs/deployment.md)::

    async for frame in NatsRiderSubscriber("nats://stage-host:4222", stage="A", rig="r1").frames():
        print(frame.seq, frame.values["head.rz"], frame.horse["root.ty"])

The websocket client of a service is :mod:`riderlive.client` (its :class:`RiderFrame`, the same here).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Any

from riderlive.client import RiderFrame, decode_binary_frame, load_codecs


class NatsRiderSubscriber:
    """Follows one rig's ``riderlive.v1.<stage>.<rig>.frame`` subject over NATS.

    Every frame carries all rider and horse channels. Channel names come from the rig's
    status (``state`` request, retried until the rig answers). Latest-only: when the
    caller is slower than the rig, older frames are dropped (counted in ``dropped``). The
    NATS connection reconnects by itself; ``restarted`` is set when the rig's session changed.
    """

    def __init__(
        self,
        url: str,
        *,
        stage: str,
        rig: str,
        user: str | None = None,
        password: str | None = None,
        creds: str | None = None,
        queue: int = 4,
    ) -> None:
        from riderlive.bus.subjects import Stage

        load_codecs()
        self.url = url
        self.subjects = Stage(stage).rig(rig)
        self.credentials = (user, password, creds)
        self.queue_size = queue
        self.status: dict[str, Any] = {}
        self.dropped = 0
        self.restarted = False
        self._closed = False

    def close(self) -> None:
        self._closed = True

    async def frames(self) -> AsyncIterator[RiderFrame]:
        """Rider frames until :meth:`close`."""
        import orjson

        from riderlive.bus.nats import Credentials, connect
        from riderlive.bus.subjects import Kind
        from riderlive.bus.transport import Message, NoResponders
        from riderlive.channels import HORSE_NAMES

        user, password, creds = self.credentials
        transport = await connect(self.url, Credentials(user=user, password=password, creds=creds), "riderlive client")
        queue: asyncio.Queue[bytes] = asyncio.Queue(self.queue_size)

        async def on_frame(msg: Message) -> None:
            if queue.full():
                queue.get_nowait()
                self.dropped += 1
            queue.put_nowait(msg.data)

        async def on_status(msg: Message) -> None:
            status = orjson.loads(msg.data)
            self.restarted = self.restarted or (
                bool(self.status) and status.get("session") != self.status.get("session")
            )
            self.status = status

        try:
            while not self.status and not self._closed:
                try:
                    state = await transport.request(self.subjects.subject(Kind.CONTROL), b'{"action":"state"}', 2.0)
                    self.status = orjson.loads(state)
                except (NoResponders, TimeoutError):
                    await asyncio.sleep(0.5)
            await transport.subscribe(self.subjects.subject(Kind.STATUS), on_status, 16)
            await transport.subscribe(self.subjects.subject(Kind.FRAME), on_frame, 1024)
            while not self._closed:
                try:
                    data = await asyncio.wait_for(queue.get(), 0.5)
                except TimeoutError:
                    continue
                obj = decode_binary_frame(data) if data[:4] == b"RLF1" else json.loads(data)
                names = self.status.get("channels", [])
                yield RiderFrame(
                    seq=obj["seq"],
                    t=obj["t"],
                    source_t=obj["source_t"],
                    driver=obj["driver"],
                    values=dict(zip(names, obj["values"], strict=False)),
                    horse=dict(zip(HORSE_NAMES, obj.get("horse", []), strict=False)),
                )
        finally:
            await transport.close()
