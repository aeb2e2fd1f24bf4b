"""The web side of e-stops (latch + wake) and of requests to the tick that want a reply
(arm, disarm, reset, reload, tune): one :class:`TickRequests` per service, on its event loop.

A request gets a reply from the tick, or a ``tick_down`` refusal when the tick is
restarting, does not answer within its timeout, or dies meanwhile (:meth:`fail_all`).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import Callable

from riderlive.devices.latch import StopSource
from riderlive.devices.lifecycle import Refusal
from riderlive.realtime import commands as cmd
from riderlive.realtime.link import TickLink

_ids = itertools.count(1)


class TickRequests:
    """Requests to the tick of ``link``; ``recovering()``: a failover is under way;
    ``last_exit()``: why the last generation ended (for the refusal's message)."""

    def __init__(self, link: TickLink, recovering: Callable[[], bool], last_exit: Callable[[], str | None]) -> None:
        self.link = link
        self.recovering = recovering
        self.last_exit = last_exit
        self.pending: dict[int, asyncio.Future[cmd.Reply]] = {}

    def estop(self, source: StopSource) -> float:
        """Latch an e-stop (shared memory, at once) and wake the tick; the request time."""
        at = self.link.latch.request(source)
        with contextlib.suppress(OSError, ValueError):  # a tick that is down: the latch holds,
            self.link.send(cmd.EStop())  # and the next one starts in estop
        return at

    async def ask(self, build: Callable[[int], cmd.Request], timeout: float = 2.0) -> cmd.Reply:
        """Send a request to the tick and wait for its reply."""
        if self.recovering() or self.link.down_reason is not None:
            return cmd.Reply(0, False, {}, Refusal.TICK_DOWN.value, f"the tick is restarting ({self.last_exit()})")
        request = next(_ids)
        future: asyncio.Future[cmd.Reply] = asyncio.get_running_loop().create_future()
        self.pending[request] = future
        try:
            command = build(request)
            self.link.send(command)
            reply = await asyncio.wait_for(future, timeout)
            if reply.ok and isinstance(command, cmd.Tune):  # a run-time setting: the next generation keeps it
                self.link.keep_tune(command.device, command.changes)
            return reply
        except (TimeoutError, OSError, ValueError):
            return cmd.Reply(request, False, {}, Refusal.TICK_DOWN.value, f"the tick did not answer in {timeout:g} s")
        finally:
            self.pending.pop(request, None)

    def on_replies(self) -> None:
        """The command pipe is readable: hand each reply to its request."""
        for reply in self.link.replies():
            future = self.pending.get(reply.request)
            if future is not None and not future.done():
                future.set_result(reply)

    def fail_all(self, message: str) -> None:
        """The tick is gone: every request waiting for it is refused with ``message``."""
        for future in self.pending.values():
            if not future.done():
                future.set_result(cmd.Reply(0, False, {}, Refusal.TICK_DOWN.value, message))
