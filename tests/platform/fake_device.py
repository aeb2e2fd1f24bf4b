"""A scripted device on a pseudo-terminal, for what the real firmware never does (a wrong
version, silence, replayed or corrupted frames, a port that vanishes). It speaks the real
link: frames built with the codec, the host's frames decoded with it."""

from __future__ import annotations

import os
import select
import threading
import tty
from collections.abc import Callable

from riderlive.platform import link, link_vocab
from riderlive.platform.link_framing import Deframer, LinkError


class FakeDevice:
    def __init__(self, on_frame: Callable[[FakeDevice, link.Frame], None] | None = None) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self.frames: list[link.Frame] = []
        self.received = threading.Event()
        self._on_frame = on_frame
        self._closed = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        deframer = Deframer()
        while not self._closed:
            if not select.select([self.master], [], [], 0.01)[0]:
                continue
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            for packet in deframer.feed(data):
                try:
                    frame = link.decode(packet)
                except LinkError:
                    continue
                self.frames.append(frame)
                self.received.set()
                if self._on_frame:
                    self._on_frame(self, frame)

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def vanish(self) -> None:
        """Close both ends, as a USB adapter pulled out: the host's next read fails."""
        self._closed = True
        self._thread.join()
        os.close(self._slave)
        os.close(self.master)


def reply_hello(version: int = link.LINK_VERSION, seq: int = 10) -> Callable[[FakeDevice, link.Frame], None]:
    """An ``on_frame`` that answers HELLO with a HELLO_REPLY in ``version``."""

    def on_frame(device: FakeDevice, frame: link.Frame) -> None:
        if isinstance(frame.message, link.Hello):
            reply = link.HelloReply((9, 9), link_vocab.Profile.SERVO8, 8, 4000, 200, "fake")
            device.write(link.encode(reply, seq, version=version))

    return on_frame


def telemetry(positions: int, state: link_vocab.LinkState = link_vocab.LinkState.RUNNING) -> link.Telemetry:
    return link.Telemetry(state, 0, 0, 0, 0, (positions,) * 8, (positions,) * 8, (0,) * len(link.COUNTERS))
