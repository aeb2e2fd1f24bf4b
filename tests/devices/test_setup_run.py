"""A plug's setup run a slice at a time (riderlive/devices/setup_run.py): steps, a busy port, the bound."""

from __future__ import annotations

import time
from collections import Counter

import pytest

from riderlive.devices import setup_run
from riderlive.devices.lifecycle import PortBusy, SetupTimeout
from riderlive.devices.setup_run import SetupRun

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
