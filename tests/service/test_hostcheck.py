"""What ``serve`` tells an installation with a serial device about its host: pure advice
from given facts, the facts read from this machine, and the warning of a live server."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from riderlive.devices.registry import DeviceSpec
from riderlive.service.hostcheck import (
    CAP_SYS_NICE,
    HostFacts,
    HostIssue,
    advise,
    device_ports,
    gather,
    has_sys_nice,
    parse_has_capability,
    parse_steal_share,
)
from riderlive.service.kworkers import kthreadd_children, normal_workers
from tests.service.live_server import LiveServer

GOOD = HostFacts(cpus=4, isolated="3", realtime_allowed=True, latency_timers_ms={"/dev/ttyUSB0": 1}, steal_share=0.0)


def issues(facts: HostFacts, tick_realtime: bool = True, web_priority: int = 10) -> list[HostIssue]:
    return [a.issue for a in advise(facts, tick_realtime, web_priority)]


def test_a_well_set_up_host_gets_no_advice() -> None:
    assert issues(GOOD) == []
    assert issues(GOOD, web_priority=0) == []  # spare cores: the web process may stay at normal priority


def test_each_problem_is_named_with_its_fix() -> None:
    slow = HostFacts(4, "3", True, {"/dev/ttyUSB1": 16, "/dev/pts/4": None}, 0.0)
    (advice,) = advise(slow, True, 10)
    assert advice.issue is HostIssue.LATENCY_TIMER and "16 ms" in advice.message
    assert "echo 1 > /sys/bus/usb-serial/devices/ttyUSB1/latency_timer" in advice.fix
    assert issues(HostFacts(4, "3", False, {}, 0.0)) == [HostIssue.NO_REALTIME]
    assert issues(HostFacts(4, "3", False, {}, 0.0), tick_realtime=False) == [HostIssue.REALTIME_OFF]
    shared = HostFacts(2, "", True, {}, 0.0)
    assert issues(shared) == [HostIssue.SHARED_CORES]
    assert issues(shared, web_priority=0) == [HostIssue.SHARED_CORES, HostIssue.WEB_PRIORITY]
    assert issues(HostFacts(2, "1", True, {}, 0.0)) == []  # a core isolated for the tick
    assert issues(HostFacts(4, "3", True, {}, 0.01)) == [HostIssue.STEAL]
    assert "1.0%" in str(advise(HostFacts(4, "3", True, {}, 0.01), True, 10)[0])


def test_kernel_workers_at_normal_priority_are_named_with_the_key_that_raises_them() -> None:
    normal = HostFacts(4, "3", True, {}, 0.0, normal_kernel_workers=5)
    (advice,) = advise(normal, True, 10)
    assert advice.issue is HostIssue.KERNEL_WORKERS and advice.message.startswith("5 unbound kernel workers")
    assert "[host] kernel_workers_priority = 1" in advice.fix and "riderlive host tune" in advice.fix
    assert advise(normal, True, 10, kernel_workers_priority=1) == []  # the service raises them
    assert issues(HostFacts(4, "3", True, {}, 0.0, normal_kernel_workers=0)) == []  # raised by the host
    unprivileged = HostFacts(4, "3", True, {}, 0.0, normal_kernel_workers=5, sys_nice=False)
    (advice,) = advise(unprivileged, True, 10, kernel_workers_priority=1)
    assert advice.issue is HostIssue.KERNEL_WORKERS and "CAP_SYS_NICE" in advice.fix


def test_capabilities_are_read_from_cap_eff() -> None:
    assert parse_has_capability("Name:\tx\nCapEff:\t0000000000800000\n", CAP_SYS_NICE)
    assert not parse_has_capability("CapEff:\t00000000007fffff\n", CAP_SYS_NICE)
    assert not parse_has_capability("Name:\tx\n", CAP_SYS_NICE)


def test_steal_share_is_read_from_the_cpu_line() -> None:
    text = "cpu  600 0 200 100 50 0 25 25 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\n"
    assert parse_steal_share(text) == pytest.approx(25 / 1000)
    assert parse_steal_share("intr 1\n") == 0.0


def test_this_hosts_facts(tmp_path: Path) -> None:
    facts = gather(["/dev/null"])
    assert facts.cpus >= 1 and 0.0 <= facts.steal_share < 1.0
    assert facts.latency_timers_ms == {"/dev/null": None}  # not an FTDI adapter
    assert facts.sys_nice is has_sys_nice() and (os.geteuid() != 0 or facts.sys_nice)
    assert normal_workers() <= len(kthreadd_children()) and facts.normal_kernel_workers <= len(kthreadd_children())
    rig = DeviceSpec("dynamixel", "bench3", None, "bench3", 1, 0.01)
    platform = DeviceSpec("platform", "stewart6", "/dev/pts/9", "stewart6", 1, 0.01)
    assert device_ports([rig, platform]) == ["/dev/ttyUSB0", "/dev/pts/9"]  # the rig map's own port


def test_serve_warns_at_start_when_a_device_is_configured(shared_rig: LiveServer) -> None:
    """Said before the server listens, so in its log once it is up (whatever the rig does since)."""
    log = "".join(shared_rig.log)
    # the rig server runs its tick without real-time priority: serve says so, with the fix
    assert "riderlive serve: warning: tick.realtime_priority is off" in log
    assert "fix: set tick.realtime_priority = true" in log
