"""A plug's setup run a slice at a time (riderlive/devices/setup_run.py): steps, a busy port, the bound."""

from __future__ import annotations

import time
from collections import Counter

import pytest

from riderlive.devices import setup_run
from riderlive.devices.lifecycle import PortBusy, SetupTimeout
from riderlive.devices.setup_run import Handback, SetupRun

from .memory_plug import MemoryPlug


def test_one_step_a_call_with_no_budget_and_the_details_said() -> None:
    plug, said, counters = MemoryPlug(), [], Counter[str]()
    run = SetupRun(plug, said.append, counters)
    assert said == ["opening the transport"] and not plug.open  # nothing runs before the first advance
    assert run.advance(0.0) is False and plug.open and said[-1] == "opening"
    assert run.advance(0.0) is False and said[-1] == "checking" and plug.outputs == [True] * 3
    assert run.advance(0.0) is True and plug.outputs == [False] * 3 and plug.log == ["setup"]
    assert run.detail == "checking" and not counters


def test_a_budget_runs_every_step_at_once() -> None:
    plug = MemoryPlug()
    assert SetupRun(plug, lambda _: None, Counter()).advance(10.0) is True
    assert plug.log == ["setup"]


def test_a_busy_port_starts_the_setup_over_and_is_counted() -> None:
    plug, said, counters = MemoryPlug(), [], Counter[str]()
    plug.fail_next["check"] = PortBusy("held by the guardian")
    run = SetupRun(plug, said.append, counters)
    assert run.advance(10.0) is False  # opened, then the check found the port busy
    assert counters["port_busy"] == 1 and said[-1] == "waiting for the transport: held by the guardian"
    assert run.advance(10.0) is True and plug.log == ["setup"]


def test_past_its_bound_the_setup_closes_and_raises(monkeypatch: pytest.MonkeyPatch) -> None:
    plug, counters = MemoryPlug(), Counter[str]()
    run = SetupRun(plug, lambda _: None, counters)
    assert run.advance(0.0) is False and plug.open
    monkeypatch.setattr(setup_run, "SETUP_TIMEOUT_S", 0.0)
    run.since = time.perf_counter() - 1.0
    with pytest.raises(SetupTimeout, match=r"still connecting after 1\.\d s \(bound 0 s\): opening"):
        run.advance(10.0)
    assert not plug.open


def test_a_first_connect_after_a_failover_waits_for_the_hand_back_without_touching_the_transport() -> None:
    plug, said, counters = MemoryPlug(), [], Counter[str]()
    held = ["waiting for the guardian to park and hand back generation 2 (guardian: parking)"]
    run = SetupRun(plug, said.append, counters, Handback(lambda: held[0] if held else None, 60.0))
    assert run.waiting and said == held and counters["handback_waits"] == 1
    for _ in range(5):  # held: nothing opened, nothing written, whatever the budget
        assert run.advance(10.0) is False
    assert not plug.open and plug.log == [] and plug.outputs == [True] * 3 and counters["handback_waits"] == 1
    held.clear()  # handed back: the setup runs as any connect
    assert run.advance(10.0) is True and not run.waiting
    assert said[1:] == ["opening the transport", "opening", "checking"] and plug.log == ["setup"]
    assert plug.outputs == [False] * 3 and counters["handback_timeouts"] == 0


def test_a_hand_back_that_never_comes_faults_at_its_bound_and_the_transport_stays_untouched() -> None:
    plug, counters = MemoryPlug(), Counter[str]()
    run = SetupRun(plug, lambda _: None, counters, Handback(lambda: "the guardian still holds generation 4", 0.05))
    assert run.advance(10.0) is False
    run.since = time.perf_counter() - 0.06  # past the bound (0.05 s) without sleeping
    with pytest.raises(SetupTimeout, match=r"not connected: the guardian still holds generation 4 for 0\.\d s \(bound"):
        run.advance(10.0)
    assert not plug.open and plug.log == [] and counters["handback_timeouts"] == 1 and not run.waiting


def test_the_setup_bound_counts_from_the_hand_back(monkeypatch: pytest.MonkeyPatch) -> None:
    plug, held = MemoryPlug(), [True]
    run = SetupRun(plug, lambda _: None, Counter(), Handback(lambda: "held" if held else None, 60.0))
    monkeypatch.setattr(setup_run, "SETUP_TIMEOUT_S", 0.5)
    run.since = time.perf_counter() - 1.0  # a wait of 1 s: longer than the setup's own bound
    assert run.advance(0.0) is False
    held.clear()
    assert run.advance(0.0) is False and plug.open  # opened: the wait was not charged to the setup
