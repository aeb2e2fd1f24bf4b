"""E-stops and requests to the tick (``service/requests.py``) against a fake link: a reply is
handed to its request, a tick that goes down refuses every waiting one, a restarting tick
and a silent one are refused with ``tick_down``, a kept tune is remembered."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any, cast

from riderlive.devices.latch import StopSource
from riderlive.devices.lifecycle import Refusal
from riderlive.realtime import commands as cmd
from riderlive.realtime.link import TickLink
from riderlive.service.requests import TickRequests


@dataclass
class FakeLatch:
    requested: list[StopSource] = field(default_factory=list)

    def request(self, source: StopSource) -> float:
        self.requested.append(source)
        return 12.5


@dataclass
class FakeLink:
    latch: FakeLatch = field(default_factory=FakeLatch)
    sent: list[Any] = field(default_factory=list)
    inbox: list[cmd.Reply] = field(default_factory=list)
    tunes: list[tuple[str, dict[str, Any]]] = field(default_factory=list)
    down_reason: str | None = None
    broken: bool = False

    def send(self, command: Any) -> None:
        if self.broken:
            raise OSError("the pipe is closed")
        self.sent.append(command)

    def replies(self) -> list[cmd.Reply]:
        out, self.inbox = self.inbox, []
        return out

    def keep_tune(self, device: str, changes: dict[str, Any]) -> None:
        self.tunes.append((device, changes))


def requests(recovering: bool = False) -> tuple[TickRequests, FakeLink]:
    link = FakeLink()
    return TickRequests(cast(TickLink, link), lambda: recovering, lambda: "died (SIGKILL)"), link


def test_an_estop_latches_and_wakes_the_tick_even_when_its_pipe_is_gone() -> None:
    reqs, link = requests()
    assert reqs.estop(StopSource.REST) == 12.5
    assert link.latch.requested == [StopSource.REST] and isinstance(link.sent[0], cmd.EStop)
    link.broken = True
    assert reqs.estop(StopSource.NATS) == 12.5 and link.latch.requested[-1] is StopSource.NATS


def test_a_reply_reaches_its_request_and_a_tune_is_kept() -> None:
    async def scenario() -> cmd.Reply:
        reqs, link = requests()
        asking = asyncio.ensure_future(reqs.ask(lambda r: cmd.Tune("bench3", {"gain": 2.0}, "page", r)))
        await asyncio.sleep(0)
        (request,) = reqs.pending
        link.inbox.append(cmd.Reply(request + 1000, True, {}, None, "someone else's"))
        link.inbox.append(cmd.Reply(request, True, {"ok": 1}, None, "done"))
        reqs.on_replies()
        reply = await asking
        assert link.tunes == [("bench3", {"gain": 2.0})] and reqs.pending == {}
        return reply

    reply = asyncio.run(scenario())
    assert reply.ok and reply.message == "done"


def test_a_tick_that_goes_down_refuses_every_waiting_request() -> None:
    async def scenario() -> list[cmd.Reply]:
        reqs, _ = requests()
        waiting = [asyncio.ensure_future(reqs.ask(lambda r: cmd.Reset(request=r))) for _ in range(3)]
        await asyncio.sleep(0)
        reqs.fail_all("the tick died (SIGKILL)")
        return list(await asyncio.gather(*waiting))

    for reply in asyncio.run(scenario()):
        assert not reply.ok and reply.refusal == Refusal.TICK_DOWN.value and "SIGKILL" in reply.message


def test_restarting_and_silent_ticks_are_refused() -> None:
    restarting, _ = requests(recovering=True)
    reply = asyncio.run(restarting.ask(lambda r: cmd.Reset(request=r)))
    assert reply.refusal == Refusal.TICK_DOWN.value and "restarting (died (SIGKILL))" in reply.message
    silent, _ = requests()
    reply = asyncio.run(silent.ask(lambda r: cmd.Reset(request=r), timeout=0.01))
    assert reply.refusal == Refusal.TICK_DOWN.value and "did not answer in 0.01 s" in reply.message
