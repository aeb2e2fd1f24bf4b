"""Keeping a warm spare (``service/spares.py``) against a fake link: started once serving, a failed
one replaced after the retry delay, doubling per failure in a row, reset by a warm one."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, cast

import pytest

from riderlive.realtime.link import TickLink
from riderlive.realtime.spare import Warm
from riderlive.service.spares import MAX_RETRY_S, SPARE_RETRY_S, SpareKeeper


@dataclass
class FakeProcess:
    alive: bool = True
    exitcode: int | None = None
    pid: int = 4242

    def is_alive(self) -> bool:
        return self.alive


@dataclass
class FakeSpare:
    process: FakeProcess = field(default_factory=FakeProcess)
    warm: Any = None
    failed: str | None = None
    discarded: bool = False

    def poll(self) -> None:
        pass

    def discard(self) -> None:
        self.discarded = True


@dataclass
class FakeLink:
    spares_wanted: bool = True
    cold_failover: bool = False
    spare: FakeSpare | None = None
    spares_started: int = 0
    spares_failed: int = 0

    def start_spare(self) -> FakeSpare:
        self.spare = FakeSpare()
        self.spares_started += 1
        return self.spare


def keeper() -> tuple[SpareKeeper, FakeLink]:
    link = FakeLink()
    return SpareKeeper(cast(TickLink, link)), link


def test_a_spare_starts_only_while_serving_and_a_warm_one_is_kept() -> None:
    spares, link = keeper()
    spares.check(1.0, serving=False)
    assert link.spares_started == 0 and not spares.warm()
    spares.check(1.0, serving=True)
    assert link.spares_started == 1 and spares.snapshot()["state"] == "warming"
    assert link.spare is not None
    link.spare.warm = Warm(4242, 1.6, 2.5)
    spares.check(2.0, serving=True)
    assert link.spares_started == 1 and spares.warm() and spares.snapshot()["state"] == "warm"
    assert spares.snapshot()["warm_up_s"] == 2.5 and spares.snapshot()["pid"] == 4242


def test_failed_spares_are_replaced_after_a_doubling_delay() -> None:
    spares, link = keeper()
    now = 10.0
    delays = []
    for _ in range(8):
        spares.check(now, serving=True)  # starts one
        assert link.spare is not None
        link.spare.failed = "ImportError: boom"
        failed = link.spare
        spares.check(now, serving=True)  # finds it failed: discarded, the next one later
        assert failed.discarded and link.spare is None
        delays.append(spares.next_at - now)
        spares.check(spares.next_at - 1e-6, serving=True)
        assert link.spare is None, "not before the retry delay"
        now = spares.next_at
    assert delays == pytest.approx([min(SPARE_RETRY_S * 2**k, MAX_RETRY_S) for k in range(8)])
    assert link.spares_failed == 8
    spares.check(now, serving=True)
    assert link.spare is not None
    link.spare.warm = Warm(4242, 1.6, 2.5)
    spares.check(now, serving=True)
    assert spares.failures == 0  # a warm one ends the run of failures


def test_a_spare_that_died_is_replaced_and_none_is_wanted_for_a_tick_thread() -> None:
    spares, link = keeper()
    spares.check(0.0, serving=True)
    assert link.spare is not None
    link.spare.process.alive, link.spare.process.exitcode = False, -9
    spares.check(0.0, serving=True)
    assert link.spares_failed == 1 and link.spare is None
    thread, tlink = keeper()
    tlink.spares_wanted = False
    thread.check(0.0, serving=True)
    assert tlink.spares_started == 0 and thread.warm()  # nothing to wait for


def test_with_the_spare_off_none_is_started_and_a_failover_counts_as_cold() -> None:
    """``tick.spare = false``: no spare ever, the status says ``off``, and :meth:`warm` is
    False so the hang threshold keeps ``hang_floor_cold`` (a failover is a cold start);
    the live wiring is checked on the shared test server (test_control)."""
    spares, link = keeper()
    link.spares_wanted, link.cold_failover = False, True
    for now in (0.0, 1.0, 100.0):
        spares.check(now, serving=True)
    assert link.spares_started == 0 and link.spare is None and not spares.warm()
    assert spares.snapshot() == {"state": "off", "pid": None, "warm_up_s": None, "started": 0, "failed": 0}
